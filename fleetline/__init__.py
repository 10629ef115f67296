"""What every fleetline package shares and nothing else: the error root (`fleetline.errors`).
Imports nothing of `gcs`, `vehicles`, `medium`, `planner` or `fleetwire`."""
