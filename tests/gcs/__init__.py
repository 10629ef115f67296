"""The ground station's tests: policies on simulated time, drivers, CLI, recording, evaluation."""
