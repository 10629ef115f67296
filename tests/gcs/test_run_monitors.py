"""Run-time monitors, the mission clock and the vehicle clock (pure parts of the runtime)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fleetwire.messages import clock_slipped_text, parse_clock_slipped
from gcs.drivers.base import VEHICLE_REBOOT_JUMP_S
from gcs.flight.clock import MissionClock, VehicleClock
from gcs.monitors import NEAR_HYSTERESIS_M, LinkMonitor, SafetyMonitor
from planner.obstacles import Obstacles

BOX = np.array([[10.0, -5.0], [20.0, -5.0], [20.0, 5.0], [10.0, 5.0]])


def monitor(size: int = 3) -> SafetyMonitor:
    return SafetyMonitor(
        fleet_size=size,
        obstacles=Obstacles(polygons=(BOX,)),
        base_stations=np.array([[0.0, 0.0]]),
        radio_range=50.0,
        safety_margin=5.0,
        vehicle_radius=0.5,
    )


def test_distances_warn_below_the_margins_and_fail_on_contact():
    safety = monitor()
    far = np.array([[0.0, 0.0], [0.0, 20.0], [0.0, 40.0]])
    assert safety.positions(0.0, far) == []
    assert safety.stats.connected_fraction == 1.0

    near = np.array([[0.0, 0.0], [0.0, 8.0], [23.0, 0.0]])  # 8 m apart, 3 m from the box
    kinds = sorted(e.kind for e in safety.positions(1.0, near))
    assert kinds == ["near_obstacle", "near_uav"]
    assert all(not e.fatal for e in safety.positions(1.0, near))
    assert safety.positions(1.1, near) == []  # reported when it starts, not at every sample

    crash = np.array([[0.0, 0.0], [0.0, 0.6], [10.2, 0.0]])  # 0.6 m apart, inside the box
    events = {e.kind: e for e in safety.positions(2.0, crash)}
    assert events["collision_uav"].fatal and "UAVs 1 and 2" in events["collision_uav"].text
    assert events["collision_obstacle"].fatal
    assert safety.stats.min_uav_uav_m == pytest.approx(0.6)
    assert safety.stats.min_uav_obstacle_m == 0.0

    safety.positions(3.0, far)  # cleared ...
    again = safety.positions(4.0, crash)  # ... and reported again
    assert {e.kind for e in again} >= {"collision_uav", "collision_obstacle"}


def test_a_distance_hovering_at_the_margin_warns_once_until_it_clearly_clears():
    """The plan flies at exactly rho_c from obstacles: noise around 5 m must not flood the log."""
    safety = monitor(size=1)

    def at(distance: float) -> np.ndarray:
        return np.array([[20.0 + distance, 0.0]])  # `distance` m east of the box

    hovering = [4.98, 5.01, 4.97, 5.02, 4.99, 6.5, 4.96]  # never clearly above 5 + hysteresis
    warnings = [e for k, d in enumerate(hovering) for e in safety.positions(float(k), at(d))]
    assert [e.kind for e in warnings] == ["near_obstacle"]
    assert safety.positions(10.0, at(5.0 + NEAR_HYSTERESIS_M + 0.1)) == []  # clearly away ...
    again = safety.positions(11.0, at(4.9))  # ... so the next approach is reported
    assert [e.kind for e in again] == ["near_obstacle"]


def test_unknown_positions_do_not_count_as_connected_samples():
    safety = monitor()
    partly = np.array([[0.0, 0.0], [np.nan, np.nan], [0.0, 40.0]])
    safety.positions(0.0, partly)
    assert safety.stats.samples == 0
    cut_off = np.array([[0.0, 0.0], [0.0, 20.0], [0.0, 200.0]])
    safety.positions(1.0, cut_off)
    assert safety.stats.connected_fraction == 0.0


def test_tracking_error_at_the_margin_is_fatal():
    safety = monitor()
    events = safety.tracking(1.0, np.array([0, 2]), np.array([1.0, 5.0]), np.array([0.5, 4.0]))
    assert [(e.uav, e.fatal) for e in events] == [(3, True)]
    assert safety.stats.max_tracking_error_m.tolist() == [1.0, 0.0, 5.0]
    assert safety.stats.max_control_error_m.tolist() == [0.5, 0.0, 4.0]


def test_link_lost_back_and_a_vehicle_known_gone():
    links = LinkMonitor(2, link_timeout_s=3.0)
    assert links.check(0.0, np.array([0.1, 0.1]), 0.3) == []
    (lost,) = links.check(1.0, np.array([0.1, 0.5]), 0.3)
    assert (lost.kind, lost.uav, lost.fatal) == ("link_lost", 2, True)
    (back,) = links.check(2.0, np.array([0.1, 0.0]), 0.3)
    assert (back.kind, back.uav) == ("link_back", 2)
    (gone,) = links.mark_lost(3.0, 0, "its process exited", silent_s=0.05)
    assert gone.uav == 1 and gone.fatal
    assert links.check(3.1, np.array([0.15, 0.0]), 0.3) == []  # still lost: no new message
    assert links.lost[0]
    (back,) = links.check(3.2, np.array([0.01, 0.0]), 0.3)  # a message arrived again
    assert back.uav == 1 and links.ever_lost.tolist() == [True, True]


def test_mission_clock_speedup_and_log_time():
    wall = [50.0]
    clock = MissionClock(4.0, monotonic=lambda: wall[0], unix_ns=lambda: 1_000 * 10**9)
    assert not clock.anchored
    clock.anchor(50.0, -8.0)
    assert clock.mission_time(52.0) == pytest.approx(0.0)
    assert clock.wall_at(4.0) == pytest.approx(53.0)
    assert clock.log_time_ns(52.0) == 1_000 * 10**9 + 2 * 10**9  # Unix time at mission 0
    assert clock.log_time_ns(53.0) - clock.log_time_ns(52.0) == 4 * 10**9


@settings(max_examples=50, derandomize=True, deadline=None)
@given(
    st.floats(0, 1000),
    st.lists(st.floats(0, 0.5), min_size=5, max_size=60),
)
def test_vehicle_clock_recovers_sample_times_from_delayed_receipts(offset, delays):
    """Samples every 0.1 s of vehicle time, received late by `delays`: the mapped times are
    never later than the true ones by more than the smallest delay seen so far."""
    clock = VehicleClock(VEHICLE_REBOOT_JUMP_S, window=100)
    smallest = float("inf")
    for k, delay in enumerate(delays):
        vehicle = 0.1 * k
        smallest = min(smallest, delay)
        mapped = clock.mission_time(vehicle, offset + vehicle + delay)
        assert offset + vehicle - 1e-9 <= mapped <= offset + vehicle + smallest + 1e-9


def test_holding_the_mission_clock_back_keeps_mission_and_log_time_continuous():
    """A stall of 2.5 mission s of which the vehicles flew 1 s: the clock stands still at the
    last tick while the backlog is read, then resumes 1 s after the last tick, on the same log
    time base."""
    clock = MissionClock(5.0, monotonic=lambda: 50.0, unix_ns=lambda: 1_000 * 10**9)
    clock.anchor(50.0, 0.0)
    last_tick, resumed = 52.0, 52.5  # wall: 10 s, then 12.5 s of mission time
    assert clock.freeze(last_tick) == pytest.approx(10.0)
    assert clock.mission_time(52.4) == pytest.approx(10.0)  # the backlog is stamped at 10 s
    assert clock.raw_mission_time(52.4) == pytest.approx(12.0)
    assert clock.resume(resumed, 11.0) == pytest.approx(11.0)
    assert clock.mission_time(resumed) == pytest.approx(11.0)
    assert clock.log_time_ns(resumed) == 1_000 * 10**9 + 11 * 10**9  # epoch kept
    assert clock.wall_at(11.0) == pytest.approx(resumed)


def test_the_mission_clock_never_runs_backwards():
    """A resume earlier than where the clock stood holds it there (a pause never rewinds), and
    a reading for an earlier wall time after a resume never goes below the resume."""
    clock = MissionClock(2.0, monotonic=lambda: 0.0, unix_ns=lambda: 0)
    clock.anchor(0.0, 0.0)
    clock.freeze(10.0)  # stands at 20 s
    assert clock.resume(15.0, 5.0) == pytest.approx(20.0)
    assert clock.mission_time(15.0) == pytest.approx(20.0)
    assert clock.mission_time(12.0) == pytest.approx(20.0)  # a stale wall time
    readings = [clock.mission_time(15.0 + 0.1 * k) for k in range(20)]
    assert readings == sorted(readings)


def test_a_sample_taken_while_the_mission_paused_maps_to_the_pause():
    """Samples every 0.1 s of vehicle time, received 20 ms late (so mapped 20 ms late); the GCS
    stalls from mission time 10 s for 2.5 s, the vehicles fly 1 s of it: the mission pauses at
    11 s for 1.5 s. Samples before the pause keep their time, those taken while the mission
    stood still map to the pause, later ones are 1.5 s earlier than before."""
    clock = VehicleClock(VEHICLE_REBOOT_JUMP_S)
    offset, delay = 100.0, 0.02  # mission time = vehicle time + offset, until the stall
    for k in range(101):  # vehicle time 0 .. 10 s, read as they come
        vehicle = 0.1 * k
        mapped = clock.mission_time(vehicle, offset + vehicle + delay)
        assert mapped == pytest.approx(offset + vehicle + delay)
    pause = offset + 11.0 + delay
    clock.pause(pause, 1.5)
    queued = [10.1 + 0.1 * k for k in range(24)]  # taken during the stall, read at its end
    mapped = [clock.mission_time(v, pause) for v in queued]
    assert mapped == pytest.approx([min(offset + v + delay, pause) for v in queued])
    assert mapped[-1] == pytest.approx(pause) and mapped[0] < pause - 0.8
    after = [clock.mission_time(v, offset + v - 1.5 + delay) for v in (12.6, 12.7, 15.0)]
    assert after == pytest.approx([pause + 0.1, pause + 0.2, pause + 2.5])


def test_a_vehicle_clock_that_slipped_maps_its_samples_to_when_they_were_taken():
    """The vehicles' simulator could not keep up and slipped 1.02 s: its clock fell that much
    behind the mission clock, as it says (STATUSTEXT). Samples every 0.1 s, received 20 ms
    after they were taken, keep mapping to when they were taken, not 1.02 s early for the
    rest of the window (5 s of samples) as the minimum offset alone would."""
    clock = VehicleClock(VEHICLE_REBOOT_JUMP_S)
    offset, delay, slip = 100.0, 0.02, 1.02
    for k in range(60):
        clock.mission_time(0.1 * k, offset + 0.1 * k + delay)
    text = clock_slipped_text(slip)
    clock.slipped(parse_clock_slipped(text))
    for k in range(60, 80):  # taken at mission time offset + 0.1 k + slip
        taken = offset + 0.1 * k + slip
        assert clock.mission_time(0.1 * k, taken + delay) == pytest.approx(taken + delay)


def test_only_a_clock_slip_report_moves_the_vehicle_clock():
    assert parse_clock_slipped(clock_slipped_text(0.25)) == pytest.approx(0.25)
    for text in ("Sim: clock slipped nan s", "Sim: clock slipped -1 s", "Guided: no setpoint"):
        assert parse_clock_slipped(text) is None


def test_a_sample_overtaken_on_the_way_keeps_the_vehicle_clock_a_reboot_restarts_it():
    """A network that reorders datagrams hands over a sample a little older than the latest:
    it maps like any other and the offset estimate is kept (it used to restart as after a
    reboot, mapping the next samples by one delayed receipt). A clock that jumps back by more
    than `VEHICLE_REBOOT_JUMP_S` is a reboot: the estimate starts over."""
    clock = VehicleClock(VEHICLE_REBOOT_JUMP_S)
    offset = 100.0
    for k in range(30):  # 0.1 s apart, received 20 ms late; the least delayed bound is kept
        clock.mission_time(0.1 * k, offset + 0.1 * k + (0.02 if k else 0.0))
    overtaken = clock.mission_time(2.85, offset + 2.95)  # taken before the last, read late
    assert overtaken == pytest.approx(offset + 2.85)
    after = clock.mission_time(3.0, offset + 3.3)  # a late receipt: mapped by the old bound
    assert after == pytest.approx(offset + 3.0)
    rebooted = clock.mission_time(0.5, offset + 10.0)  # back 2.5 s: a reboot
    assert rebooted == pytest.approx(offset + 10.0)
