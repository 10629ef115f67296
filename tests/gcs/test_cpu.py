"""The idle CPU a flight measures and the speed-up it picks from it (`gcs.sim.cpu`): injected
jiffies and spare cores, no real wait."""

from __future__ import annotations

import pytest

from gcs.sim.cpu import MIN_SHARE, affordable_speedup, spare_cores


def test_an_idle_machine_flies_at_the_nominal_speedup():
    assert affordable_speedup(5, spare=2.0, cores=2) == 5.0
    assert affordable_speedup(5, spare=1.0, cores=2) == 5.0  # a core besides the flight's own
    assert affordable_speedup(10, spare=7.0, cores=8) == 10.0


def test_a_fully_busy_machine_flies_at_the_lowest_share():
    assert MIN_SHARE == 0.4
    assert affordable_speedup(5, spare=0.0, cores=2) == 2.0
    assert affordable_speedup(10, spare=-1.5, cores=8) == 4.0  # load average above the cores


def test_a_half_idle_machine_flies_at_half_the_speedup():
    assert affordable_speedup(5, spare=0.5, cores=2) == 2.5
    assert affordable_speedup(8, spare=3.5, cores=8) == 4.0


def test_the_speedup_is_rounded_to_a_tenth():
    assert affordable_speedup(5, spare=0.62, cores=2) == 3.1  # 3.1
    assert affordable_speedup(4, spare=0.77, cores=2) == 3.1  # 3.08
    assert affordable_speedup(5, spare=0.33, cores=2) == 2.0  # 1.65 is below 0.4 x 5


def _readings(*times: tuple[int, int]):
    """A `read_times` that returns `times` in turn."""
    queue = list(times)
    return lambda: queue.pop(0)


def test_spare_cores_is_the_idle_share_of_the_window_times_the_cores():
    waited: list[float] = []
    spare = spare_cores(
        0.5,
        cores=2,
        read_times=_readings((1000, 4000), (1030, 4100)),  # 30 of 100 jiffies idle
        sleep=waited.append,
    )
    assert spare == pytest.approx(0.6)
    assert waited == [0.5]


def test_a_window_without_jiffies_counts_every_core_idle():
    spare = spare_cores(cores=4, read_times=_readings((10, 50), (10, 50)), sleep=lambda _: None)
    assert spare == 4.0


def test_unreadable_times_fall_back_to_the_load_average():
    def unreadable() -> tuple[int, int]:
        raise OSError("no /proc/stat")

    spare = spare_cores(
        cores=2, read_times=unreadable, sleep=lambda _: None, load_average=lambda: 1.25
    )
    assert spare == 0.75


def test_proc_stat_is_read_as_idle_plus_iowait_against_all(tmp_path):
    from gcs.sim import cpu

    stat = tmp_path / "stat"
    stat.write_text("cpu  10 20 30 400 50 6 7 8 9 10\ncpu0 1 2 3 4 5 6 7 8 9 10\n")
    assert cpu.proc_stat_times(stat) == (450, 531)
