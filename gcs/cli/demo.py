"""`python -m gcs.cli.demo` (`make demo`): plan the paper's scenario and fly it on the simulated
fleet.

Plans `examples/table-ii.yaml` and draws it into `logs/demo-plan.png`, then flies it with nine
simulated vehicles (one process), about a minute and a half at 5x real time: 5x on an idle
machine, slower on a busy one (the idle CPU measured just before, `gcs.sim.cpu`), said in one
line before the flight. The recording goes to `logs/`, the summary to the terminal.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from gcs import cli
from gcs.sim.cpu import affordable_speedup, spare_cores

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "table-ii.yaml"
PLOT = Path("logs") / "demo-plan.png"
SPEEDUP = 5  # on an idle machine


def main() -> int:
    PLOT.parent.mkdir(parents=True, exist_ok=True)
    status = cli.main(["mission", "plan", str(EXAMPLE), "--plot", str(PLOT)])
    if status != 0:
        return status
    cores = os.cpu_count() or 1
    spare = spare_cores(cores=cores)
    speedup = affordable_speedup(SPEEDUP, spare, cores)
    print(
        f"demo: {spare:.1f} cores idle of {cores}: flying at {speedup:.1f}x"
        f" ({SPEEDUP}x on an idle machine)",
        flush=True,
    )
    return cli.main(
        ["mission", "run", str(EXAMPLE), "--speedup", str(speedup), "--vehicles-per-process", "9"]
    )


if __name__ == "__main__":
    sys.exit(main())
