"""Starting the processes a simulated run needs (vehicles, radio medium) beside the GCS.

Each child gets a process group of its own, so that Ctrl-C in the terminal reaches the ground
station only (it decides: freeze, then land), but stays in the GCS's session: the kernel's
scheduler groups a session's processes (autogroup), and a child in a session of its own would
get as much CPU as the whole ground station. Children run at a slightly lower priority
(`CHILD_NICENESS`): on a busy machine the ground station's setpoints come first, and a
vehicle falling behind is seen on its own clock (MAVLink time_boot_ms).
"""

from __future__ import annotations

import logging
import os
import subprocess
from pathlib import Path

log = logging.getLogger(__name__)

#: How much lower than the GCS's the children's scheduling priority is (nice increment).
CHILD_NICENESS = 3


def start_child(cmd: list[str], *, root: Path, stderr=subprocess.DEVNULL) -> subprocess.Popen:
    """Start `cmd` with `root` (the tree holding `vehicles`) on its PYTHONPATH."""
    path = os.pathsep.join(filter(None, [str(root), os.environ.get("PYTHONPATH")]))
    process = subprocess.Popen(
        cmd,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=stderr,
        env={**os.environ, "PYTHONUNBUFFERED": "1", "PYTHONPATH": path},
        process_group=0,  # Ctrl-C in the terminal reaches the GCS only
    )
    try:
        current = os.getpriority(os.PRIO_PROCESS, process.pid)
        os.setpriority(os.PRIO_PROCESS, process.pid, min(current + CHILD_NICENESS, 19))
    except (AttributeError, OSError) as error:  # not POSIX, or the child is already gone
        log.debug("could not lower the priority of %s: %s", cmd[0], error)
    return process
