"""The point-mass dynamics and position controller (pure, seeded): tracking, limits, ground,
wind rejection, noise statistics and determinism."""

from __future__ import annotations

import dataclasses

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from vehicles.dynamics import Airframe, Disturbances, DynamicsConfig, FleetDynamics
from vehicles.testing import SmoothedPath

QUIET = DynamicsConfig(disturbances=Disturbances().scaled(0.0))


def flying(config: DynamicsConfig, start=(0.0, 0.0, 30.0), seeds=((1, 1),)) -> FleetDynamics:
    """Vehicles airborne at ``start``, motors on, holding."""
    starts = np.array([start] * len(seeds), dtype=float)
    dynamics = FleetDynamics(config, starts, seeds)
    dynamics.ground_z[:] = -100.0
    dynamics.motors_on[:] = True
    dynamics.grounded[:] = False
    for i in range(len(seeds)):
        dynamics.hold(i, starts[i])
    return dynamics


def fly_square(config: DynamicsConfig, rate_hz: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    """Stream a smoothed 200 m square at 10 m/s like a GCS (pos + vel + acc, 10 Hz)."""
    corners = np.array(
        [[0, 0, 30], [200, 0, 30], [200, 200, 30], [0, 200, 30], [0, 0, 30]], dtype=float
    )
    path = SmoothedPath(corners, speed_mps=10.0, window_s=3.0)
    dynamics = flying(config)
    every = round(1.0 / rate_hz / config.step_s)
    times = np.arange(-2.0, path.duration_s + 5.0, config.step_s)
    true = np.empty((len(times), 3))
    for k, t in enumerate(times):
        if k % every == 0:
            position, velocity, acceleration = path.sample(t)
            dynamics.set_reference(0, position, velocity, acceleration, horizon_s=1.0)
        dynamics.step(1)
        true[k] = dynamics.position[0]
    reference = path.sample(times + config.step_s)[0]
    return true - reference, true


def test_tracks_a_smoothed_square_at_10_mps_with_feed_forward():
    error, _ = fly_square(QUIET)
    assert np.linalg.norm(error, axis=1).max() < 0.5
    noisy, _ = fly_square(DynamicsConfig())  # the navigation noise adds its own (true) error
    horizontal = np.hypot(noisy[:, 0], noisy[:, 1])
    assert horizontal.max() < 1.2
    assert np.sqrt(np.mean(horizontal**2)) < 0.5


def test_a_far_position_step_is_flown_at_the_speed_limit_without_overshoot():
    dynamics = flying(QUIET)
    dynamics.hold(0, np.array([300.0, 0.0, 30.0]))
    track = []
    for _ in range(6000):
        dynamics.step(1)
        track.append(dynamics.position[0].copy())
    track = np.array(track)
    speed = np.hypot(*np.diff(track[:, :2], axis=0).T) / QUIET.step_s
    assert 14.5 < speed.max() <= 15.0 * 1.01
    assert track[:, 0].max() - 300.0 < 0.5  # the square-root controller plans its braking
    assert abs(track[-1, 0] - 300.0) < 0.05


@settings(derandomize=True, max_examples=25, deadline=None)
@given(
    target=st.tuples(
        st.floats(-400, 400, allow_nan=False),
        st.floats(-400, 400, allow_nan=False),
        st.floats(0, 120),
    ),
    velocity=st.tuples(st.floats(-30, 30), st.floats(-30, 30), st.floats(-10, 10)),
    max_speed=st.floats(3, 20),
    max_acceleration=st.floats(1, 8),
)
def test_speed_acceleration_and_climb_limits_hold(target, velocity, max_speed, max_acceleration):
    airframe = Airframe(max_speed_mps=max_speed, max_acceleration_mps2=max_acceleration)
    config = dataclasses.replace(QUIET, airframe=airframe)
    dynamics = flying(config, start=(0.0, 0.0, 50.0))
    dynamics.set_reference(0, np.array(target), np.array(velocity), horizon_s=1.0)
    velocities, thrusts = [], []
    for _ in range(800):
        dynamics.step(1)
        velocities.append(dynamics.velocity[0].copy())
        thrusts.append(dynamics.thrust_acceleration[0].copy())
    velocities, thrusts = np.array(velocities), np.array(thrusts)
    assert np.hypot(velocities[:, 0], velocities[:, 1]).max() <= max_speed * 1.03 + 0.05
    assert velocities[:, 2].max() <= airframe.max_climb_mps * 1.03 + 0.05
    assert (
        velocities[:, 2].min() >= -airframe.max_descent_mps * 1.03 - 0.05 - 0.5
    )  # + gravity transients
    assert np.hypot(thrusts[:, 0], thrusts[:, 1]).max() <= max_acceleration + 1e-9
    assert np.abs(thrusts[:, 2]).max() <= airframe.max_vertical_acceleration_mps2 + 1e-9


def test_mean_wind_is_rejected_by_the_integrator():
    config = dataclasses.replace(
        QUIET, disturbances=Disturbances(wind_mean_mps=(6.0, -4.0, 0.0)).scaled(0.0)
    )
    dynamics = flying(config)
    dynamics.step(3000)
    offsets = []
    for _ in range(500):
        dynamics.step(1)
        offsets.append(np.linalg.norm(dynamics.position[0] - [0.0, 0.0, 30.0]))
    assert max(offsets) < 0.05


def test_navigation_noise_has_the_configured_spread_and_is_coloured():
    disturbances = Disturbances(
        gust_sigma_mps=0.0, navigation_sigma_m=0.5, navigation_time_constant_s=1.0
    )
    config = dataclasses.replace(QUIET, disturbances=disturbances)
    dynamics = flying(config, seeds=[(5, k) for k in range(20)])
    samples = []
    for _ in range(600):
        dynamics.step(5)
        samples.append(dynamics.navigation_error[:, 0].copy())
    samples = np.array(samples)
    assert 0.4 < samples.std() < 0.6
    lag1 = np.corrcoef(samples[:-1].ravel(), samples[1:].ravel())[0, 1]  # 50 ms apart
    assert 0.9 < lag1 < 0.99  # exp(-0.05 / 1.0) = 0.95


def test_each_vehicle_flies_the_same_whether_alone_or_in_a_fleet():
    config = DynamicsConfig()
    alone = flying(config, start=(0.0, 0.0, 30.0), seeds=[(7, 3)])
    fleet = flying(config, start=(0.0, 0.0, 30.0), seeds=[(7, 1), (7, 2), (7, 3)])
    for dynamics in (alone, fleet):
        dynamics.hold(dynamics.count - 1, np.array([40.0, 10.0, 35.0]))
        dynamics.step(700)
    np.testing.assert_array_equal(alone.position[0], fleet.position[2])
    assert not np.array_equal(fleet.position[0], fleet.position[2])


def test_ground_contact_take_off_and_touch_down():
    dynamics = FleetDynamics(QUIET, np.zeros((1, 3)), [(1, 1)])
    dynamics.step(200)  # disarmed: stays put
    assert dynamics.grounded[0] and np.allclose(dynamics.position[0], 0.0)
    dynamics.motors_on[0] = True
    dynamics.hold(0, np.array([0.0, 0.0, -1.0]))  # armed, pushing down: stays grounded
    dynamics.step(200)
    assert dynamics.grounded[0] and dynamics.position[0, 2] == 0.0
    dynamics.hold(0, np.array([0.0, 0.0, 10.0]))
    dynamics.step(1500)
    assert not dynamics.grounded[0] and abs(dynamics.position[0, 2] - 10.0) < 0.05
    dynamics.set_limits(0, speed=15.0, climb=2.5, descent=0.5)
    dynamics.hold(0, np.array([0.0, 0.0, -1.0]))
    lowest = 10.0
    for _ in range(3000):
        dynamics.step(1)
        lowest = min(lowest, dynamics.position[0, 2])
    assert dynamics.grounded[0] and lowest == 0.0
    assert dynamics.velocity[0, 2] == 0.0


def test_a_vehicle_without_motors_falls():
    dynamics = flying(QUIET, start=(0.0, 0.0, 20.0))
    dynamics.ground_z[:] = 0.0
    dynamics.motors_on[0] = False
    dynamics.step(300)
    assert dynamics.grounded[0] and dynamics.position[0, 2] == 0.0
