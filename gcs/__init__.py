"""Ground-control station: mission model, CLI, orchestration of planner, fleet and recording."""
