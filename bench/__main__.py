"""Run every benchmark module (bench/bench_*.py, each with a `main()` that prints its table),
after the machine's speed today (`bench.machine`)."""

from __future__ import annotations

import importlib
import pkgutil
import sys

import bench
from bench import machine


def main(argv: list[str]) -> int:
    wanted = set(argv)
    machine.main()
    names = sorted(
        m.name for m in pkgutil.iter_modules(bench.__path__) if m.name.startswith("bench_")
    )
    for name in names:
        if wanted and name.removeprefix("bench_") not in wanted and name not in wanted:
            continue
        importlib.import_module(f"bench.{name}").main()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
