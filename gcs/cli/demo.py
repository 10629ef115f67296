"""`python -m gcs.cli.demo` (`make demo`): plan the paper's scenario and fly it on the simulated
fleet.

Plans `examples/table-ii.yaml` and draws it into `logs/demo-plan.png`, then flies it with nine
simulated vehicles (one process) at 5x real time, about a minute and a half: the recording goes
to `logs/`, the summary to the terminal.
"""

from __future__ import annotations

import sys
from pathlib import Path

from gcs import cli

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "table-ii.yaml"
PLOT = Path("logs") / "demo-plan.png"
SPEEDUP = 5


def main() -> int:
    PLOT.parent.mkdir(parents=True, exist_ok=True)
    status = cli.main(["mission", "plan", str(EXAMPLE), "--plot", str(PLOT)])
    if status != 0:
        return status
    return cli.main(
        ["mission", "run", str(EXAMPLE), "--speedup", str(SPEEDUP), "--vehicles-per-process", "9"]
    )


if __name__ == "__main__":
    sys.exit(main())
