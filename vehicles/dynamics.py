"""Vectorised 3-D point-mass dynamics of a fleet of multicopters (pure: no sockets, files, clocks).

Frame: local ENU metres (x east, y north, z up) relative to the simulation's geodetic origin.
Each vehicle is a point mass whose net acceleration is the commanded acceleration passed through
a first-order lag (attitude and thrust response, ``thrust_time_constant_s``) plus the push of the
wind through a linear drag. The position controller is a cascade in the style of ArduCopter's
``AC_PosControl``: a square-root position controller (linear near the target, constant
deceleration far from it) with velocity feed-forward, then a PI velocity controller with
acceleration feed-forward, with limits on horizontal speed, climb and descent rates and on
horizontal and vertical accelerations. The controller acts on the *estimated* state (true
position plus navigation noise), as a real autopilot does, so the navigation noise shows up in
the true tracking error.

Disturbances are seeded per vehicle (``seed_sequence`` of each vehicle), so a vehicle flies the
same way whether it shares a process with others or not:
* wind: mean wind plus gusts as an Ornstein-Uhlenbeck (coloured) process per axis;
* navigation noise: an Ornstein-Uhlenbeck error on the estimated position.

The reference of each vehicle is (position, velocity, acceleration) at ``reference_time``; the
controller extrapolates it kinematically for up to ``reference_horizon`` seconds, so a 10 Hz
setpoint stream of a moving target is followed without a saw-tooth lag.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

GRAVITY_MPS2 = 9.80665
_NOISE_BLOCK_STEPS = 100
_SLOW_STATE_STEPS = 5  # heading and battery are updated every this many steps


@dataclass(frozen=True)
class Airframe:
    """Physical limits and response of one multicopter (defaults: a ~2 kg quad, ArduCopter-like)."""

    max_speed_mps: float = 15.0  # horizontal
    max_climb_mps: float = 2.5  # WPNAV_SPEED_UP
    max_descent_mps: float = 1.5  # WPNAV_SPEED_DN
    max_acceleration_mps2: float = 6.0  # horizontal
    max_vertical_acceleration_mps2: float = 4.0
    max_yaw_rate_dps: float = 90.0
    thrust_time_constant_s: float = 0.1  # lag between commanded and achieved acceleration
    drag_per_s: float = 0.15  # linear drag: acceleration per m/s of air-relative velocity
    battery_capacity_mah: float = 8000.0
    battery_cells: int = 3
    hover_power_w: float = 180.0
    avionics_power_w: float = 5.0


@dataclass(frozen=True)
class Controller:
    """Position/velocity controller gains (ArduCopter PSC_* defaults scaled to SI units)."""

    position_gain: float = 1.0  # 1/s, PSC_POSXY_P
    velocity_gain: float = 2.5  # 1/s, PSC_VELXY_P
    velocity_integral_gain: float = 1.0  # 1/s^2, PSC_VELXY_I
    integral_limit_mps2: float = 2.0  # bound of the integral term
    integral_band_mps: float = 0.5  # the integral only acts on velocity errors below this
    shaping_acceleration_mps2: float = 3.0  # deceleration the square-root controller plans with


@dataclass(frozen=True)
class Disturbances:
    """Wind (mean + Ornstein-Uhlenbeck gusts) and navigation noise (Ornstein-Uhlenbeck)."""

    wind_mean_mps: tuple[float, float, float] = (0.0, 0.0, 0.0)  # east, north, up
    gust_sigma_mps: float = 1.0  # horizontal, per axis
    gust_sigma_vertical_mps: float = 0.3
    gust_time_constant_s: float = 5.0
    navigation_sigma_m: float = 0.2  # horizontal, per axis
    navigation_sigma_vertical_m: float = 0.3
    navigation_time_constant_s: float = 2.0

    def scaled(self, factor: float) -> Disturbances:
        """The same disturbances with gusts and navigation noise multiplied by ``factor``."""
        return Disturbances(
            wind_mean_mps=self.wind_mean_mps,
            gust_sigma_mps=self.gust_sigma_mps * factor,
            gust_sigma_vertical_mps=self.gust_sigma_vertical_mps * factor,
            gust_time_constant_s=self.gust_time_constant_s,
            navigation_sigma_m=self.navigation_sigma_m * factor,
            navigation_sigma_vertical_m=self.navigation_sigma_vertical_m * factor,
            navigation_time_constant_s=self.navigation_time_constant_s,
        )


@dataclass(frozen=True)
class DynamicsConfig:
    """Everything the fleet dynamics needs besides the start positions and seeds."""

    step_s: float = 0.01
    airframe: Airframe = field(default_factory=Airframe)
    controller: Controller = field(default_factory=Controller)
    disturbances: Disturbances = field(default_factory=Disturbances)


class FleetDynamics:
    """State and fixed-step integration of N vehicles; the autopilots write the references.

    Public arrays (one row per vehicle): ``position``, ``velocity``, ``thrust_acceleration``
    (commanded-and-achieved acceleration, gravity excluded), ``wind``, ``navigation_error``,
    ``yaw`` (rad, NED heading), ``ground_z``, ``grounded``, ``motors_on``, ``energy_used_j``.
    Reference arrays: ``reference_position/velocity/acceleration``, ``reference_time``,
    ``reference_horizon``, ``use_position/velocity/acceleration``, ``speed_limit``,
    ``climb_limit``, ``descent_limit``, ``yaw_target`` (NaN: face the direction of travel).
    """

    def __init__(
        self,
        config: DynamicsConfig,
        start_positions: np.ndarray,
        seed_sequences: Sequence[Sequence[int]],
    ) -> None:
        start = np.asarray(start_positions, dtype=float).reshape(-1, 3)
        count = start.shape[0]
        if len(seed_sequences) != count:
            raise ValueError("one seed sequence per vehicle is needed")
        self.config = config
        self.count = count
        self.time_s = 0.0
        airframe = config.airframe
        dist = config.disturbances
        # vectors are stored (3, N) for cheap per-axis rows in the hot loop; the public
        # (N, 3) attributes are transposed views of the same memory
        self._position = np.ascontiguousarray(start.T)
        self._velocity = np.zeros((3, count))
        self._thrust = np.zeros((3, count))
        self._integral = np.zeros((3, count))
        self._wind = np.tile(np.asarray(dist.wind_mean_mps, dtype=float)[:, None], (1, count))
        self._navigation = np.zeros((3, count))
        self._reference_position = self._position.copy()
        self._reference_velocity = np.zeros((3, count))
        self._reference_acceleration = np.zeros((3, count))
        self.position = self._position.T
        self.velocity = self._velocity.T
        self.thrust_acceleration = self._thrust.T
        self.wind = self._wind.T
        self.navigation_error = self._navigation.T
        self.integral = self._integral.T  # velocity-loop integral
        self.reference_position = self._reference_position.T
        self.reference_velocity = self._reference_velocity.T
        self.reference_acceleration = self._reference_acceleration.T
        self.yaw = np.zeros(count)
        self.ground_z = start[:, 2].copy()
        self.grounded = np.ones(count, dtype=bool)
        self.motors_on = np.zeros(count, dtype=bool)
        self.energy_used_j = np.zeros(count)
        self.power_w = np.zeros(count)
        self.reference_time = np.zeros(count)
        self.reference_horizon = np.zeros(count)
        self.use_position = np.ones(count, dtype=bool)
        self.use_velocity = np.zeros(count, dtype=bool)
        self.use_acceleration = np.zeros(count, dtype=bool)
        self.speed_limit = np.full(count, airframe.max_speed_mps)
        self.climb_limit = np.full(count, airframe.max_climb_mps)
        self.descent_limit = np.full(count, airframe.max_descent_mps)
        self.yaw_target = np.full(count, np.nan)
        self._generators = [np.random.default_rng(list(s)) for s in seed_sequences]
        # initial wind and navigation error from their stationary distributions
        gust_sigma = np.array(
            [dist.gust_sigma_mps, dist.gust_sigma_mps, dist.gust_sigma_vertical_mps]
        )
        nav_sigma = np.array(
            [dist.navigation_sigma_m, dist.navigation_sigma_m, dist.navigation_sigma_vertical_m]
        )
        for i, generator in enumerate(self._generators):
            draw = generator.standard_normal(6)
            self._wind[:, i] += draw[:3] * gust_sigma
            self._navigation[:, i] = draw[3:] * nav_sigma
        self._noise = np.zeros((0, 6, count))
        self._noise_index = 0
        self._slow_pending = 0

    # -- estimated state (what the autopilot knows and reports) ----------------------------
    def estimated(self, index: int) -> np.ndarray:
        """Estimated position of vehicle ``index``, (3,) (a new array)."""
        return self._position[:, index] + self._navigation[:, index]

    def stopping_point(self, index: int) -> np.ndarray:
        """Where vehicle ``index`` stops if it decelerates now at the shaping deceleration."""
        decel = self.config.controller.shaping_acceleration_mps2
        velocity = self.velocity[index]
        point = self.position[index] + self.navigation_error[index]
        horizontal = velocity.copy()
        horizontal[2] = 0.0
        speed = float(np.hypot(velocity[0], velocity[1]))
        point = point + horizontal * (speed / (2.0 * decel))
        point[2] += (
            velocity[2]
            * abs(velocity[2])
            / (2.0 * self.config.airframe.max_vertical_acceleration_mps2)
        )
        return point

    # -- references ------------------------------------------------------------------------
    def set_reference(
        self,
        index: int,
        position: np.ndarray | None,
        velocity: np.ndarray | None = None,
        acceleration: np.ndarray | None = None,
        horizon_s: float = 0.0,
        time_s: float | None = None,
    ) -> None:
        """Track ``position`` (None: velocity control) with optional feed-forwards."""
        self.use_position[index] = position is not None
        self.use_velocity[index] = velocity is not None
        self.use_acceleration[index] = acceleration is not None
        if position is not None:
            self.reference_position[index] = position
        self.reference_velocity[index] = velocity if velocity is not None else 0.0
        self.reference_acceleration[index] = acceleration if acceleration is not None else 0.0
        self.reference_time[index] = self.time_s if time_s is None else time_s
        self.reference_horizon[index] = (
            horizon_s if (velocity is not None or acceleration is not None) else 0.0
        )

    def hold(self, index: int, point: np.ndarray) -> None:
        """Hold position at ``point`` (no feed-forward)."""
        self.set_reference(index, np.asarray(point, dtype=float))

    def reference_now(self, index: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The extrapolated reference (position, velocity, acceleration) of vehicle ``index``."""
        tau = min(max(self.time_s - self.reference_time[index], 0.0), self.reference_horizon[index])
        acc = self.reference_acceleration[index]
        vel = self.reference_velocity[index] + acc * tau
        pos = (
            self.reference_position[index]
            + self.reference_velocity[index] * tau
            + 0.5 * acc * tau * tau
        )
        return pos, vel, acc

    def set_limits(self, index: int, speed: float, climb: float, descent: float) -> None:
        airframe = self.config.airframe
        self.speed_limit[index] = min(speed, airframe.max_speed_mps)
        self.climb_limit[index] = min(climb, airframe.max_climb_mps)
        self.descent_limit[index] = min(descent, airframe.max_descent_mps)

    # -- integration -----------------------------------------------------------------------
    def _start_noise(self) -> None:
        blocks = [g.standard_normal((_NOISE_BLOCK_STEPS, 6)) for g in self._generators]
        self._noise = np.stack(blocks, axis=2) if blocks else np.zeros((_NOISE_BLOCK_STEPS, 6, 0))
        self._noise_index = 0

    def step(self, count: int = 1) -> None:
        """Advance the whole fleet by ``count`` fixed steps."""
        done = 0
        while done < count:
            chunk = min(count - done, _SLOW_STATE_STEPS - self._slow_pending)
            self._integrate(chunk)
            done += chunk
            self._slow_pending += chunk
            if self._slow_pending >= _SLOW_STATE_STEPS:
                self._update_heading_and_battery(self._slow_pending * self.config.step_s)
                self._slow_pending = 0

    def _integrate(self, count: int) -> None:
        """The hot loop: position/velocity controller, thrust lag, physics and disturbances."""
        cfg = self.config
        dt = cfg.step_s
        af = cfg.airframe
        ctl = cfg.controller
        dist = cfg.disturbances
        kp, kv, ki = ctl.position_gain, ctl.velocity_gain, ctl.velocity_integral_gain
        decel_h = min(ctl.shaping_acceleration_mps2, af.max_acceleration_mps2)
        decel_v = min(ctl.shaping_acceleration_mps2, af.max_vertical_acceleration_mps2)
        linear_h, linear_v = decel_h / (kp * kp), decel_v / (kp * kp)
        integral_limit = ctl.integral_limit_mps2 / ki if ki > 0 else 0.0
        integral_band = ctl.integral_band_mps
        tc = af.thrust_time_constant_s
        thrust_alpha = 1.0 - np.exp(-dt / tc) if tc > 0 else 1.0
        gust_phi = np.exp(-dt / dist.gust_time_constant_s)
        nav_phi = np.exp(-dt / dist.navigation_time_constant_s)
        gust_scale = (
            np.sqrt(1.0 - gust_phi**2)
            * np.array([dist.gust_sigma_mps, dist.gust_sigma_mps, dist.gust_sigma_vertical_mps])[
                :, None
            ]
        )
        nav_scale = (
            np.sqrt(1.0 - nav_phi**2)
            * np.array(
                [dist.navigation_sigma_m, dist.navigation_sigma_m, dist.navigation_sigma_vertical_m]
            )[:, None]
        )
        wind_drift = (1.0 - gust_phi) * np.asarray(dist.wind_mean_mps, dtype=float)[:, None]
        drag = af.drag_per_s
        max_acc_h, max_acc_v = af.max_acceleration_mps2, af.max_vertical_acceleration_mps2
        use_pos = self.use_position.astype(float)
        use_vel = self.use_velocity.astype(float)
        use_acc = self.use_acceleration.astype(float)
        closed = (self.use_position | self.use_velocity).astype(float)
        closed_dt = closed * dt
        motors = self.motors_on.astype(float)
        falling = (motors - 1.0) * GRAVITY_MPS2  # -g with the motors off
        speed_limit, climb, descent = self.speed_limit, self.climb_limit, -self.descent_limit
        position, velocity, thrust = self._position, self._velocity, self._thrust
        integral, nav, wind = self._integral, self._navigation, self._wind
        ref_p, ref_v, ref_a = (
            self._reference_position,
            self._reference_velocity,
            self._reference_acceleration,
        )
        ref_a_ff = ref_a * use_acc
        ground = self.ground_z
        ground_eps = ground + 1e-6
        for _ in range(count):
            if self._noise_index >= self._noise.shape[0]:
                self._start_noise()
            noise = self._noise[self._noise_index]
            self._noise_index += 1
            # reference, extrapolated along its feed-forward for up to its horizon
            tau = self.time_s - self.reference_time
            np.maximum(tau, 0.0, out=tau)
            np.minimum(tau, self.reference_horizon, out=tau)
            vel_ref = ref_a * tau
            error = vel_ref * 0.5
            error += ref_v
            error *= tau
            error += ref_p
            vel_ref += ref_v
            # position loop: square-root controller (horizontal on the norm) + velocity feed-forward
            error -= position
            error -= nav
            # (linear near the target: gain kp; beyond, sqrt(2 a d) -- only computed when needed)
            err_h = np.hypot(error[0], error[1])
            far = err_h > linear_h
            if far.any():
                gain_h = np.sqrt(np.maximum(err_h - 0.5 * linear_h, 0.0) * (2.0 * decel_h))
                gain_h /= np.maximum(err_h, 1e-9)
                gain_h = np.where(far, gain_h, kp)
                error[0] *= gain_h
                error[1] *= gain_h
            else:
                error[:2] *= kp
            err_v = np.abs(error[2])
            far = err_v > linear_v
            if far.any():
                gain_v = np.sqrt(np.maximum(err_v - 0.5 * linear_v, 0.0) * (2.0 * decel_v))
                gain_v /= np.maximum(err_v, 1e-9)
                error[2] *= np.where(far, gain_v, kp)
            else:
                error[2] *= kp
            error *= use_pos
            vel_ref *= use_vel
            vel_cmd = error
            vel_cmd += vel_ref
            scale = speed_limit / np.maximum(np.hypot(vel_cmd[0], vel_cmd[1]), 1e-9)
            np.minimum(scale, 1.0, out=scale)
            vel_cmd[:2] *= scale
            np.minimum(np.maximum(vel_cmd[2], descent, out=vel_cmd[2]), climb, out=vel_cmd[2])
            # velocity loop: PI + acceleration feed-forward + the vehicle's own drag; the
            # integral only grows while the acceleration is not saturated (anti-windup)
            vel_cmd -= velocity
            vel_error = vel_cmd
            acc_cmd = vel_error * kv
            acc_cmd += integral * ki
            acc_cmd *= closed
            acc_cmd += ref_a_ff
            acc_cmd += velocity * drag
            scale = max_acc_h / np.maximum(np.hypot(acc_cmd[0], acc_cmd[1]), 1e-9)
            np.minimum(scale, 1.0, out=scale)
            acc_cmd[:2] *= scale
            vertical = np.minimum(np.maximum(acc_cmd[2], -max_acc_v), max_acc_v)
            free = closed_dt * ~self.grounded
            vel_error[:2] *= free * (scale >= 1.0)
            vel_error[2] *= free * (vertical == acc_cmd[2])
            vel_error *= np.abs(vel_error) < integral_band * dt  # only near steady state
            acc_cmd[2] = vertical
            integral += vel_error
            np.minimum(
                np.maximum(integral, -integral_limit, out=integral), integral_limit, out=integral
            )
            acc_cmd *= motors
            # achieved acceleration: first-order lag of the command
            acc_cmd -= thrust
            acc_cmd *= thrust_alpha
            thrust += acc_cmd
            # physics: thrust (or free fall with the motors off) and drag in the wind
            accel = thrust * motors
            accel[2] += falling
            accel += (wind - velocity) * drag
            resting = (position[2] <= ground_eps) & (accel[2] <= 0.0)
            any_resting = resting.any()
            if any_resting:
                accel[:, resting] = 0.0
                velocity[:, resting] = 0.0
            accel *= dt
            velocity += accel
            position += velocity * dt
            below = position[2] < ground
            if below.any():
                position[2, below] = ground[below]
                velocity[:, below] = 0.0
                resting |= below
                any_resting = True
            self.grounded = resting
            if any_resting:
                integral[:, resting] = 0.0
            # disturbances (Ornstein-Uhlenbeck, exact discretisation)
            wind *= gust_phi
            wind += wind_drift
            wind += noise[:3] * gust_scale
            nav *= nav_phi
            nav += noise[3:] * nav_scale
            self.time_s += dt

    def _update_heading_and_battery(self, duration_s: float) -> None:
        """Heading (rate-limited towards the target or the direction of travel) and energy."""
        af = self.config.airframe
        velocity, thrust = self._velocity, self._thrust
        moving = np.hypot(velocity[0], velocity[1]) > 1.0
        travel = np.where(moving, np.arctan2(velocity[0], velocity[1]), self.yaw)
        wanted = np.where(np.isnan(self.yaw_target), travel, self.yaw_target)
        turn = np.remainder(wanted - self.yaw + np.pi, 2.0 * np.pi) - np.pi
        limit = np.radians(af.max_yaw_rate_dps) * duration_s
        self.yaw = (
            np.remainder(self.yaw + np.clip(turn, -limit, limit) + np.pi, 2.0 * np.pi) - np.pi
        )
        lift = thrust[2] + GRAVITY_MPS2
        ratio = np.sqrt(thrust[0] ** 2 + thrust[1] ** 2 + lift * lift) / GRAVITY_MPS2
        self.power_w = af.avionics_power_w + af.hover_power_w * ratio**1.5 * self.motors_on
        self.energy_used_j += self.power_w * duration_s
