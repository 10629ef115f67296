"""Idle CPU now, and the speed-up a simulated flight can afford on it.

A simulated flight K times faster than real time needs the CPU to keep up: on a busy machine
it flies slower, its guarantees (rho_c) stay what they are.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path

#: The lowest share of the nominal speed-up a flight is given, however busy the machine: a
#: flight still ends in reasonable time.
MIN_SHARE = 0.4


def proc_stat_times(path: Path = Path("/proc/stat")) -> tuple[int, int]:
    """(idle + iowait, all) jiffies of every core since boot, from /proc/stat (Linux): its
    first line's user, nice, system, idle, iowait, irq, softirq and steal (guest time is
    already counted in user and nice)."""
    fields = [int(x) for x in path.read_text().splitlines()[0].split()[1:9]]
    return fields[3] + fields[4], sum(fields)


def spare_cores(
    window_s: float = 0.5,
    *,
    cores: int | None = None,
    read_times: Callable[[], tuple[int, int]] = proc_stat_times,
    sleep: Callable[[float], None] = time.sleep,
    load_average: Callable[[], float] = lambda: os.getloadavg()[0],
) -> float:
    """Cores idle now: the share of CPU time counted idle over `window_s` (`read_times`:
    (idle, all) jiffies; steal time, a busy host's, counts as busy), times the `cores`
    (default: this machine's); `cores` less the 1-minute load average when the times cannot be
    read. Measured, not averaged over the last minute: a burst of work just before must not
    slow a flight down."""
    cores = cores or os.cpu_count() or 1
    try:
        idle_before, all_before = read_times()
        sleep(window_s)  # a measurement window, not a synchronisation
        idle_after, all_after = read_times()
    except (OSError, ValueError, IndexError):
        return cores - load_average()
    idle, total = idle_after - idle_before, all_after - all_before
    return cores * idle / total if total > 0 else float(cores)


def affordable_speedup(nominal: float, spare: float, cores: int | None = None) -> float:
    """The speed-up to fly at instead of `nominal` with `spare` cores idle of `cores` (default:
    this machine's): `nominal` times the idle share of all the cores but one, kept between
    `MIN_SHARE` and 1, rounded to 0.1."""
    cores = cores or os.cpu_count() or 1
    share = min(max(spare / max(cores - 1, 1), MIN_SHARE), 1.0)
    return round(nominal * share, 1)
