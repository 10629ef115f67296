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


@dataclass(frozen=True, eq=False)
class _StepConstants:
    """What every integration step of a `DynamicsConfig` uses, computed once: scalars as 0-d
    arrays (numpy multiplies by them faster than by Python floats) and per-axis values spread
    over the fleet, (3, N) or (6, N), so that no operation of the hot loop broadcasts."""

    step_s: float
    dt: np.ndarray
    zero: np.ndarray
    one: np.ndarray
    half: np.ndarray
    tiny: np.ndarray  # the floor of the norms the limits divide by
    kp: np.ndarray
    kv: np.ndarray
    ki: np.ndarray
    unit_kp: bool  # kp == 1: the product by kp changes nothing and is skipped
    unit_ki: bool
    drag: np.ndarray
    linear: np.ndarray  # (3, N): where the square-root controller leaves its linear part
    half_linear: np.ndarray  # (3, N)
    two_decel: np.ndarray  # (3, N)
    max_acc_h: np.ndarray
    min_acc_v: np.ndarray
    max_acc_v: np.ndarray
    integral_band_dt: np.ndarray
    min_integral: np.ndarray
    max_integral: np.ndarray
    thrust_alpha: np.ndarray
    decay: np.ndarray  # (6, N): Ornstein-Uhlenbeck factor of wind and navigation error
    drift: np.ndarray  # (6, N): the wind's pull towards its mean (0 for the navigation error)
    innovation_scale: np.ndarray  # (6, 1): standard deviation of each step's innovation

    @classmethod
    def of(cls, config: DynamicsConfig, count: int) -> _StepConstants:
        dt = config.step_s
        af = config.airframe
        ctl = config.controller
        dist = config.disturbances
        kp, ki = ctl.position_gain, ctl.velocity_integral_gain
        decel_h = min(ctl.shaping_acceleration_mps2, af.max_acceleration_mps2)
        decel_v = min(ctl.shaping_acceleration_mps2, af.max_vertical_acceleration_mps2)
        linear_h, linear_v = decel_h / (kp * kp), decel_v / (kp * kp)
        integral_limit = ctl.integral_limit_mps2 / ki if ki > 0 else 0.0
        tc = af.thrust_time_constant_s
        gust_phi = np.exp(-dt / dist.gust_time_constant_s)
        nav_phi = np.exp(-dt / dist.navigation_time_constant_s)
        gust_scale = np.sqrt(1.0 - gust_phi**2) * np.array(
            [dist.gust_sigma_mps, dist.gust_sigma_mps, dist.gust_sigma_vertical_mps]
        )
        nav_scale = np.sqrt(1.0 - nav_phi**2) * np.array(
            [dist.navigation_sigma_m, dist.navigation_sigma_m, dist.navigation_sigma_vertical_m]
        )
        wind_drift = (1.0 - gust_phi) * np.asarray(dist.wind_mean_mps, dtype=float)

        def axes(values) -> np.ndarray:
            return np.repeat(np.asarray(values, dtype=float)[:, None], count, axis=1)

        return cls(
            step_s=dt,
            dt=np.array(dt),
            zero=np.array(0.0),
            one=np.array(1.0),
            half=np.array(0.5),
            tiny=np.array(1e-9),
            kp=np.array(kp),
            kv=np.array(ctl.velocity_gain),
            ki=np.array(ki),
            unit_kp=kp == 1.0,
            unit_ki=ki == 1.0,
            drag=np.array(af.drag_per_s),
            linear=axes([linear_h, linear_h, linear_v]),
            half_linear=axes([0.5 * linear_h, 0.5 * linear_h, 0.5 * linear_v]),
            two_decel=axes([2.0 * decel_h, 2.0 * decel_h, 2.0 * decel_v]),
            max_acc_h=np.array(af.max_acceleration_mps2),
            min_acc_v=np.array(-af.max_vertical_acceleration_mps2),
            max_acc_v=np.array(af.max_vertical_acceleration_mps2),
            integral_band_dt=np.array(ctl.integral_band_mps * dt),
            min_integral=np.array(-integral_limit),
            max_integral=np.array(integral_limit),
            thrust_alpha=np.array(1.0 - np.exp(-dt / tc) if tc > 0 else 1.0),
            decay=axes([gust_phi] * 3 + [nav_phi] * 3),
            drift=axes(list(wind_drift) + [0.0] * 3),
            innovation_scale=np.concatenate([gust_scale, nav_scale])[:, None],
        )


@dataclass(frozen=True, eq=False)
class _WorkArrays:
    """The hot loop's intermediate values, written in place (`out=`) at every step: no
    allocation, and the row views made once. (3, N) unless said otherwise."""

    ref_time: np.ndarray  # the references' time, spread over the axes
    horizon: np.ndarray
    integrating: np.ndarray  # the integral's step (0: on the ground or open loop)
    tau: np.ndarray
    vel_ref: np.ndarray
    error: np.ndarray  # position error, then velocity command, then velocity error
    norms: np.ndarray  # horizontal norm (rows 0, 1) and vertical magnitude of the error
    acc_cmd: np.ndarray
    accel: np.ndarray
    scratch: np.ndarray
    far: np.ndarray  # bool
    keep: np.ndarray  # bool
    hyp: np.ndarray  # (N,)
    scale: np.ndarray  # (N,)
    vertical: np.ndarray  # (N,)
    unsaturated: np.ndarray  # (N,) bool
    rows: tuple  # the row views of error, norms, acc_cmd and keep

    @classmethod
    def of(cls, count: int) -> _WorkArrays:
        shape = (3, count)
        error, norms, acc_cmd = np.empty(shape), np.empty(shape), np.empty(shape)
        keep = np.empty(shape, dtype=bool)
        return cls(
            ref_time=np.empty(shape),
            horizon=np.empty(shape),
            integrating=np.empty(shape),
            tau=np.empty(shape),
            vel_ref=np.empty(shape),
            error=error,
            norms=norms,
            acc_cmd=acc_cmd,
            accel=np.empty(shape),
            scratch=np.empty(shape),
            far=np.empty(shape, dtype=bool),
            keep=keep,
            hyp=np.empty(count),
            scale=np.empty(count),
            vertical=np.empty(count),
            unsaturated=np.empty(count, dtype=bool),
            rows=(tuple(error), tuple(norms), tuple(acc_cmd), tuple(keep)),
        )


class FleetDynamics:
    """State and fixed-step integration of N vehicles; the autopilots write the references.

    Public arrays (one row per vehicle): ``position``, ``velocity``, ``thrust_acceleration``
    (commanded-and-achieved acceleration, gravity excluded), ``wind``, ``navigation_error``,
    ``yaw`` (rad, NED heading), ``ground_z``, ``grounded``, ``motors_on``, ``energy_used_j``,
    ``battery_capacity_mah`` (the airframe's, unless given per vehicle).
    Reference arrays: ``reference_position/velocity/acceleration``, ``reference_time``,
    ``reference_horizon``, ``use_position/velocity/acceleration``, ``speed_limit``,
    ``climb_limit``, ``descent_limit``, ``yaw_target`` (NaN: face the direction of travel).
    """

    def __init__(
        self,
        config: DynamicsConfig,
        start_positions: np.ndarray,
        seed_sequences: Sequence[Sequence[int]],
        battery_capacity_mah: Sequence[float] | None = None,
    ) -> None:
        start = np.asarray(start_positions, dtype=float).reshape(-1, 3)
        count = start.shape[0]
        if len(seed_sequences) != count:
            raise ValueError("one seed sequence per vehicle is needed")
        if battery_capacity_mah is not None and len(battery_capacity_mah) != count:
            raise ValueError("one battery capacity per vehicle is needed")
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
        # wind (rows 0-2) and navigation error (rows 3-5): one array, one update per step
        self._disturbance = np.zeros((6, count))
        self._wind = self._disturbance[:3]
        self._navigation = self._disturbance[3:]
        self._wind[:] = np.asarray(dist.wind_mean_mps, dtype=float)[:, None]
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
        self.battery_capacity_mah = (
            np.full(count, airframe.battery_capacity_mah)
            if battery_capacity_mah is None
            else np.array(battery_capacity_mah, dtype=float)
        )
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
        self._step = _StepConstants.of(config, count)
        self._work = _WorkArrays.of(count)
        self._noise = np.zeros((0, 6, count))
        self._noise_index = 0
        self._slow_pending = 0

    # -- estimated state (what the autopilot knows and reports) ----------------------------
    def estimated(self, index: int) -> np.ndarray:
        """Estimated position of vehicle ``index``, (3,) (a new array)."""
        return self._position[:, index] + self._navigation[:, index]

    def stopping_point(self, index: int, deceleration: float | None = None) -> np.ndarray:
        """Where vehicle ``index`` stops if it decelerates now horizontally at ``deceleration``
        (m/s^2; None: the controller's shaping deceleration)."""
        decel = self.config.controller.shaping_acceleration_mps2
        if deceleration is not None:
            decel = deceleration
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
        """The next block of the disturbances' innovations, (steps, 6, N), already scaled."""
        blocks = [g.standard_normal((_NOISE_BLOCK_STEPS, 6)) for g in self._generators]
        noise = np.stack(blocks, axis=2) if blocks else np.zeros((_NOISE_BLOCK_STEPS, 6, 0))
        self._noise = noise * self._step.innovation_scale
        self._noise_index = 0

    def step(self, count: int = 1) -> None:
        """Advance the whole fleet by ``count`` fixed steps."""
        self._integrate(count)

    def _spread(self, row: np.ndarray) -> np.ndarray | None:
        """A per-vehicle 0/1 row spread over the three axes, (3, N); None when it is all 1
        (multiplying by it would change nothing)."""
        if np.count_nonzero(row) == self.count:
            return None
        spread = np.empty(self._position.shape)
        spread[:] = row
        return spread

    def _integrate(self, count: int) -> None:  # noqa: C901 (over 15 branches: to split)
        """The hot loop: position/velocity controller, thrust lag, physics and disturbances;
        heading and battery every `_SLOW_STATE_STEPS` steps.

        Every (3, N) operation runs on operands of its own shape (the per-vehicle rows are
        spread over the three axes once per call) and in place where it can, and a product by
        a 0/1 row that is all 1 is skipped: for a fleet of a few vehicles numpy's per-call
        overhead, not the arithmetic, is the cost, and broadcasting a row costs three times an
        operation on equal shapes."""
        c = self._step
        dt = c.dt
        position, velocity, thrust = self._position, self._velocity, self._thrust
        integral, nav, disturbance = self._integral, self._navigation, self._disturbance
        ref_p, ref_v, ref_a = (
            self._reference_position,
            self._reference_velocity,
            self._reference_acceleration,
        )
        w = self._work
        # per-vehicle settings of this call, spread over the axes
        ref_time, horizon, integrating = w.ref_time, w.horizon, w.integrating
        ref_time[:] = self.reference_time
        horizon[:] = self.reference_horizon
        use_pos = self._spread(self.use_position)
        use_vel = self._spread(self.use_velocity)
        closed_row = (self.use_position | self.use_velocity).astype(float)
        closed = self._spread(closed_row)
        closed_dt = closed_row * c.step_s
        # the integral's step: dt where the loop is closed and the vehicle is off the ground
        # (spread over the axes; recomputed only while some vehicle is on the ground)
        integrating[:] = closed_dt * ~self.grounded
        grounded_before = np.count_nonzero(self.grounded) > 0
        motors_row = self.motors_on.astype(float)
        motors = self._spread(motors_row)
        if motors is not None:
            falling = (motors_row - 1.0) * GRAVITY_MPS2  # -g with the motors off
        use_acc = self._spread(self.use_acceleration)
        ref_a_ff = ref_a if use_acc is None else ref_a * use_acc  # (only read below)
        speed_limit, climb, descent = self.speed_limit, self.climb_limit, -self.descent_limit
        ground = self.ground_z
        ground_eps = ground + 1e-6
        tau, vel_ref, error, norms = w.tau, w.vel_ref, w.error, w.norms
        acc_cmd, accel, scratch, far, keep = w.acc_cmd, w.accel, w.scratch, w.far, w.keep
        hyp, scale, vertical, unsaturated = w.hyp, w.scale, w.vertical, w.unsaturated
        (e0, e1, e2), (n0, n1, n2), (a0, a1, a2), (k0, k1, k2) = w.rows
        for _ in range(count):
            if self._noise_index >= self._noise.shape[0]:
                self._start_noise()
            noise = self._noise[self._noise_index]
            self._noise_index += 1
            # reference, extrapolated along its feed-forward for up to its horizon
            np.subtract(self.time_s, ref_time, out=tau)
            np.maximum(tau, c.zero, out=tau)
            np.minimum(tau, horizon, out=tau)
            np.multiply(ref_a, tau, out=vel_ref)
            np.multiply(vel_ref, c.half, out=error)
            error += ref_v
            error *= tau
            error += ref_p
            vel_ref += ref_v
            # position loop: square-root controller (horizontal on the norm) + velocity feed-forward
            error -= position
            error -= nav
            # (linear near the target: gain kp; beyond, sqrt(2 a d) -- only computed when needed;
            # rows 0 and 1 hold the horizontal norm, row 2 the vertical error)
            np.hypot(e0, e1, out=n0)
            np.copyto(n1, n0)
            np.absolute(e2, out=n2)
            np.greater(norms, c.linear, out=far)
            if np.count_nonzero(far):
                gain = np.subtract(norms, c.half_linear)
                np.maximum(gain, c.zero, out=gain)
                gain *= c.two_decel
                np.sqrt(gain, out=gain)
                gain /= np.maximum(norms, c.tiny)
                error *= np.where(far, gain, c.kp)
            elif not c.unit_kp:
                error *= c.kp
            if use_pos is not None:
                error *= use_pos
            if use_vel is not None:
                vel_ref *= use_vel
            error += vel_ref  # the velocity command
            np.hypot(e0, e1, out=hyp)
            np.maximum(hyp, c.tiny, out=hyp)
            np.divide(speed_limit, hyp, out=scale)
            np.minimum(scale, c.one, out=scale)
            e0 *= scale
            e1 *= scale
            np.minimum(np.maximum(e2, descent, out=e2), climb, out=e2)
            # velocity loop: PI + acceleration feed-forward + the vehicle's own drag; the
            # integral only grows while the acceleration is not saturated (anti-windup)
            error -= velocity  # the velocity error
            np.multiply(error, c.kv, out=acc_cmd)
            acc_cmd += integral if c.unit_ki else np.multiply(integral, c.ki, out=scratch)
            if closed is not None:
                acc_cmd *= closed
            acc_cmd += ref_a_ff
            acc_cmd += np.multiply(velocity, c.drag, out=scratch)
            np.hypot(a0, a1, out=hyp)
            np.maximum(hyp, c.tiny, out=hyp)
            np.divide(c.max_acc_h, hyp, out=scale)
            np.minimum(scale, c.one, out=scale)
            a0 *= scale
            a1 *= scale
            np.minimum(np.maximum(a2, c.min_acc_v, out=vertical), c.max_acc_v, out=vertical)
            error *= integrating
            np.less(np.absolute(error, out=scratch), c.integral_band_dt, out=keep)  # steady state
            np.greater_equal(scale, c.one, out=unsaturated)
            k0 &= unsaturated
            k1 &= unsaturated
            k2 &= np.equal(vertical, a2, out=unsaturated)
            error *= keep
            np.copyto(a2, vertical)
            integral += error
            np.minimum(
                np.maximum(integral, c.min_integral, out=integral), c.max_integral, out=integral
            )
            if motors is not None:
                acc_cmd *= motors
            # achieved acceleration: first-order lag of the command
            acc_cmd -= thrust
            acc_cmd *= c.thrust_alpha
            thrust += acc_cmd
            # physics: thrust (or free fall with the motors off) and drag in the wind
            if motors is not None:
                np.multiply(thrust, motors, out=accel)
                accel[2] += falling
            else:  # every motor on: nothing falls (and the thrust is never -0.0: + 0 is a no-op)
                np.copyto(accel, thrust)
            drag = np.subtract(disturbance[:3], velocity, out=scratch)
            drag *= c.drag
            accel += drag
            resting = position[2] <= ground_eps  # (all False in flight: no more tests)
            any_resting = np.count_nonzero(resting) > 0
            if any_resting:
                resting &= accel[2] <= 0.0
                any_resting = np.count_nonzero(resting) > 0
            if any_resting:
                accel[:, resting] = 0.0
                velocity[:, resting] = 0.0
            accel *= dt
            velocity += accel
            position += np.multiply(velocity, dt, out=scratch)
            below = position[2] < ground
            if np.count_nonzero(below):
                position[2, below] = ground[below]
                velocity[:, below] = 0.0
                resting |= below
                any_resting = True
            self.grounded = resting
            if any_resting or grounded_before:
                integrating[:] = closed_dt * ~resting
                grounded_before = any_resting
            if any_resting:
                integral[:, resting] = 0.0
            # disturbances: wind (rows 0-2) and navigation error (rows 3-5), Ornstein-Uhlenbeck,
            # exact discretisation (the noise block is drawn already scaled)
            disturbance *= c.decay
            disturbance += c.drift
            disturbance += noise
            self.time_s += c.step_s
            self._slow_pending += 1
            if self._slow_pending >= _SLOW_STATE_STEPS:
                self._update_heading_and_battery(self._slow_pending * c.step_s)
                self._slow_pending = 0

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
            np.remainder(
                self.yaw + np.minimum(np.maximum(turn, -limit), limit) + np.pi, 2.0 * np.pi
            )
            - np.pi
        )
        lift = thrust[2] + GRAVITY_MPS2
        ratio = np.sqrt(thrust[0] ** 2 + thrust[1] ** 2 + lift * lift) / GRAVITY_MPS2
        self.power_w = af.avionics_power_w + af.hover_power_w * ratio**1.5 * self.motors_on
        self.energy_used_j += self.power_w * duration_s
