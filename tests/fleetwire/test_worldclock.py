"""Lockstep with the simulated world: the shared world clock (fleetwire.worldclock), a
follower's simulated clock on it, and the ground station's side (gcs.flight.lockstep), on
injected wall times. The processes and the flights are test_lockstep_e2e.py's."""

from __future__ import annotations

import math

import pytest

from fleetwire.worldclock import (
    WORLD_LAG_S,
    WORLD_LEAD_S,
    FollowerClock,
    WorldClockError,
    WorldClockFollower,
    WorldClockMaster,
    check_world_clock,
)
from gcs.flight.clock import MissionClock
from gcs.flight.lockstep import WorldSync

SPEEDUP = 5.0


@pytest.fixture
def master(tmp_path):
    clock = WorldClockMaster(tmp_path / "clock", slots=3, speedup=SPEEDUP)
    yield clock
    clock.close()


def test_the_master_publishes_and_the_followers_read_and_report(master):
    follower = WorldClockFollower(master.path, 1)
    assert not follower.bounds().running  # no world before the mission clock runs
    master.publish(zero=100.0, speedup=SPEEDUP, cap=12.5)
    bounds = follower.bounds()
    assert (bounds.zero, bounds.speedup, bounds.cap) == (100.0, SPEEDUP, 12.5)
    assert bounds.world_time(101.0) == 5.0
    assert bounds.world_time(200.0) == 12.5  # never past the cap
    assert bounds.wall_at(10.0) == 102.0 and bounds.wall_at(12.6) == math.inf
    follower.report(3.25)
    progress = master.progress()
    assert progress[1] == 3.25 and math.isnan(progress[0]) and math.isnan(progress[2])
    master.release(1)
    assert master.progress()[1] == math.inf
    follower.close()


def test_only_a_world_clock_file_is_followed(tmp_path, master):
    other = tmp_path / "other"
    other.write_bytes(b"not a clock at all, but long enough to hold a header of one")
    for path in (other, tmp_path / "missing"):
        with pytest.raises(WorldClockError):
            check_world_clock(path)
        with pytest.raises(WorldClockError):
            WorldClockFollower(path, 0)
    assert check_world_clock(master.path) == master.path
    with pytest.raises(WorldClockError):
        WorldClockFollower(master.path, 3)  # slots 0..2


def test_a_follower_runs_free_then_joins_the_world_without_a_jump(master):
    """Its own clock (simulated s since it started) continues where it was when it joins, then
    moves with the world, never past the cap, never backwards when the world is held back."""
    clock = FollowerClock(SPEEDUP, wall0=10.0, world=WorldClockFollower(master.path, 0))
    clock.refresh(11.0)
    assert not clock.joined and clock.now(11.0) == 5.0  # the wall clock, times 5
    # the ground station anchors its mission clock: mission time -7 at wall 11.0
    master.publish(zero=11.0 + 7.0 / SPEEDUP, speedup=SPEEDUP, cap=-7.0 + WORLD_LEAD_S)
    clock.refresh(11.0)
    assert clock.joined and clock.now(11.0) == pytest.approx(5.0)
    assert clock.offset == pytest.approx(12.0)  # simulated = world + 12
    assert clock.now(11.02) == pytest.approx(5.1)  # on the world's pace
    assert clock.now(20.0) == pytest.approx(-7.0 + WORLD_LEAD_S + 12.0)  # held at the cap
    clock.advanced_to(5.3)
    assert master.progress()[0] == pytest.approx(5.3 - 12.0)  # reported in world time
    assert clock.wall_at(5.4) == math.inf  # past the cap: not before it rises
    # the master holds its clock back (zero later): world -7.7 at wall 15, below where this
    # follower got (world -6.7): it waits, it never rewinds, then moves on with the world
    master.publish(zero=15.0 + 7.7 / SPEEDUP, speedup=SPEEDUP, cap=10.0)
    clock.refresh(15.0)
    assert clock.now(15.0) == pytest.approx(5.3)
    assert clock.now(16.0) == pytest.approx(-2.7 + 12.0)


def test_a_follower_whose_master_is_gone_runs_on_the_wall_clock(master):
    clock = FollowerClock(SPEEDUP, wall0=0.0, world=WorldClockFollower(master.path, 2))
    master.publish(zero=0.0, speedup=SPEEDUP, cap=4.0)
    clock.refresh(1.0)
    clock.advanced_to(clock.now(1.0))  # world 4.0, the cap; simulated 5.0 (offset 1)
    assert clock.now(3.0) == pytest.approx(5.0)  # the ground station stopped: held
    clock.leave(3.0)  # orphaned: the failsafes must run
    assert master.progress()[2] == math.inf  # nobody waits for it any more
    assert clock.now(3.0) == pytest.approx(5.0) and clock.now(4.0) == pytest.approx(10.0)


# ------------------------------------------------------------------ the ground station's side
def anchored(now: float = 50.0, at: float = -5.0) -> MissionClock:
    clock = MissionClock(SPEEDUP, monotonic=lambda: 0.0, unix_ns=lambda: 0)
    clock.anchor(now, at)
    return clock


def test_the_mission_clock_waits_for_the_slowest_follower(master):
    clock = anchored()  # mission time -5 at wall 50
    world = WorldSync(master, ["vehicles 1-4", "vehicles 5-8", "radio medium"])
    followers = [WorldClockFollower(master.path, k) for k in range(3)]
    assert world.step(50.0, clock) == []
    bounds = followers[0].bounds()
    assert bounds.zero == pytest.approx(clock.wall_at(0.0))
    assert bounds.cap == pytest.approx(-5.0 + WORLD_LEAD_S)
    world.ticked(-5.0)
    for k, progress in enumerate((-4.0, -2.0, -4.5)):
        followers[k].report(progress)
    # wall 51: the clock would read 0.0; the medium (slot 2) has only reached -4.5
    world.step(51.0, clock)
    assert clock.mission_time(51.0) == pytest.approx(-4.5 + WORLD_LAG_S)
    assert clock.held_back_s == pytest.approx(4.5 - WORLD_LAG_S)
    world.ticked(clock.mission_time(51.0))
    world.step(51.0, clock)
    assert followers[0].bounds().cap == pytest.approx(-4.5 + WORLD_LAG_S + WORLD_LEAD_S)
    # the clock runs on from where it was held: no jump when the medium catches up
    followers[2].report(-3.0)
    world.step(51.1, clock)
    assert clock.mission_time(51.1) == pytest.approx(-4.5 + WORLD_LAG_S + 0.5)
    # never held back below the last tick (setpoints for it are out)
    world.ticked(clock.mission_time(51.1))
    followers[2].report(-10.0)
    world.step(51.1, clock)
    assert clock.mission_time(51.1) == pytest.approx(-4.5 + WORLD_LAG_S + 0.5)
    for follower in followers:
        follower.close()


def test_a_follower_that_never_moves_again_is_given_up_on(master):
    clock = anchored()
    world = WorldSync(master, ["vehicles 1-4", "medium"], stuck_wall_s=30.0)
    follower = WorldClockFollower(master.path, 0)
    follower.report(-5.0)  # then stopped for good
    world.step(50.0, clock)
    assert world.step(79.9, clock) == []  # held all along, still waited for
    assert clock.mission_time(79.9) == pytest.approx(-5.0 + WORLD_LAG_S)
    (text,) = world.step(80.0, clock)
    assert text.startswith("vehicles 1-4: no progress for 30 s")
    assert master.progress()[0] == math.inf and world.summary(clock)["released"] == ["vehicles 1-4"]
    world.step(81.0, clock)  # the world runs on without it, from where it was held
    assert clock.mission_time(81.0) == pytest.approx(-5.0 + WORLD_LAG_S + 1.1 * SPEEDUP)
    follower.close()


def test_hold_back_never_rewinds_a_clock_below_its_floor():
    clock = anchored()
    assert clock.hold_back(51.0, 10.0) == 0.0  # only ever back, never forward
    clock.resume(51.0, 1.0)  # a stall's resumption: the floor is 1.0
    assert clock.hold_back(51.2, 0.5) == pytest.approx(1.0)  # read 2.0, held to the floor
    assert clock.mission_time(51.2) == pytest.approx(1.0)
    assert clock.hold_back(51.4, 1.5) == pytest.approx(0.5)  # read 2.0, held to 1.5
    clock.freeze(51.5)
    assert clock.hold_back(51.6, 0.0) == 0.0  # frozen: the stall logic owns it


def test_hold_back_never_goes_below_a_mission_time_already_read():
    """Between two ticks the recorder stamped records with the clock's reading: holding the
    clock back below it would make log times run backwards (test_log_flight caught it)."""
    clock = anchored()  # mission time -5 at wall 50
    stamped = clock.mission_time(51.0)  # 0.0: a record written at this log time
    assert clock.hold_back(51.0, -4.0) == 0.0  # held to what was read, not below
    assert clock.mission_time(51.0) == pytest.approx(stamped)
    assert clock.peek(51.2) == pytest.approx(1.0)  # and runs on from there
    assert clock.hold_back(51.2, 0.5) == pytest.approx(0.5)  # peeked, not read: free to hold


def test_a_body_of_zeros_is_no_world_and_never_stops_a_follower(master):
    """Bounds of zeros (a clock file read as it is created or cut short; once seen in CI, where
    the medium divided by the zero speed-up and exited, and every link was lost) neither make
    a follower join nor replace the bounds it joined with."""
    clock = FollowerClock(SPEEDUP, wall0=0.0, world=WorldClockFollower(master.path, 0))
    master.publish(zero=0.0, speedup=0.0, cap=0.0)
    clock.refresh(1.0)
    assert not clock.joined and clock.wall_at(10.0) == pytest.approx(2.0)  # its own clock
    master.publish(zero=0.0, speedup=SPEEDUP, cap=50.0)
    clock.refresh(1.0)
    assert clock.joined
    joined_at = clock.wall_at(10.0 + clock.offset)
    master.publish(zero=0.0, speedup=0.0, cap=0.0)
    clock.refresh(2.0)
    assert clock.wall_at(10.0 + clock.offset) == joined_at == pytest.approx(2.0)
    assert clock.now(2.0) == pytest.approx(10.0 + clock.offset)
