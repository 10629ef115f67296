"""The simulated vehicles' tests."""
