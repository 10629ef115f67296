"""`python -m gcs.demo` (`make demo`): plan the paper's scenario, draw it, print the summary.

For now it plans and plots `examples/table-ii.yaml` into `logs/demo-plan.png`; flying the
mission comes with `gcs mission run`.
"""

from __future__ import annotations

import sys
from pathlib import Path

from gcs import cli

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "table-ii.yaml"
PLOT = Path("logs") / "demo-plan.png"


def main() -> int:
    PLOT.parent.mkdir(parents=True, exist_ok=True)
    return cli.main(["mission", "plan", str(EXAMPLE), "--plot", str(PLOT)])


if __name__ == "__main__":
    sys.exit(main())
