"""The planner's tests: pure, numbers in and out."""
