"""Simulated runs: the fast in-process mode (`fastsim`), the paper's evaluation (`eval`), the
radio medium process beside the GCS (`radio`), starting child processes (`children`), SITL
launch plans (`sitl`), and the speed-up the idle CPU affords (`cpu`)."""
