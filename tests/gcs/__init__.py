"""The ground station's tests: the core's policies on simulated time, drivers, CLI, recording, evaluation."""
