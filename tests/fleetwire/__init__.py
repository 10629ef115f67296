"""The shared wire's tests (signing clocks, geodesy, the world clock)."""
