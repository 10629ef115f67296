"""The radio medium's tests."""
