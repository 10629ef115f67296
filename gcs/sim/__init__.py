"""Simulated runs: the fast in-process mode (`fastsim`), the paper's evaluation (`eval`), the
radio medium process beside the GCS (`radio`), starting child processes (`children`) and SITL
launch plans (`sitl`)."""
