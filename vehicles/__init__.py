"""Simulated vehicles: MAVLink autopilot stand-ins with noisy point-mass dynamics (no planner)."""
