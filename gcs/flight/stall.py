"""Where and how the formation resumes after a stall of the ground station.

While the ground station did not run, no setpoint went out and each vehicle flew on by itself:
its autopilot carries the last setpoint on for its setpoint timeout (the position moved on by
the velocity: ArduCopter's and our simulated vehicle's GUIDED), then brakes and holds. A UAV
that lagged its target (joining the formation, accelerating) closes that gap meanwhile, faster
than the formation (12.6 m/s in a formation at 8 m/s), and brakes from there. When the backlog
has been read, the UAVs may be anywhere from standing still behind the formation to flying on
at more than its speed, a few metres ahead of it.

The formation resumes with a pause of `pause_s` inserted at mission time `at` (the targets the
UAVs match), and the mission clock set to `at + pause_s / 2`. With the moving-average reference
of width w (docs/design.md 3.5: `planner.kinematics.smoothed_reference`) a pause of length L <= w
leaves the reference, at the middle of the pause, exactly at S(at) moving at v (1 - L / w),
not accelerating, and then accelerating at v / w back to v:

* L = w is a standing start (the reference stands still: UAVs that stopped);
* L = 0 flies on at full speed (UAVs that kept flying: a stall shorter than their timeout);
* in between, UAVs still braking are picked up at their speed.

Each candidate L is judged by the worst tracking error it would cause: a UAV at x moving at u
after a reference at V moving at r closes their velocity difference at the braking
acceleration a, so its error goes from |x - V| to |x + (u - r)|u - r| / (2 a) - V| (the
distance gained meanwhile), the larger of the two being what the monitor would see. The
candidate (and the instant `at`) with the least worst error wins, ties going to the longer
pause. Matching positions alone (the old rule) resumed UAVs still flying at 8 m/s with a
standing reference, or braking ones with a reference at full speed: 7-10 m errors in the fast
mode for 1-3 s stalls (rho_c 5 m), and 5.1-5.5 m in live flights at 1x after a 1 s stall.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Stall:
    """A stall of the loop: from `since` to `until` (the loop's time) nothing ran; the mission
    clock stood at `stood_at` (the last tick); the UAVs stood where the formation was at
    `paused_at` (never earlier); the clock resumed from `resumed_at` (half a smoothing window
    later when a standing start was inserted), `held_back_s` mission seconds behind where it
    would have been (negative: ahead, the inserted pause being longer than the stall)."""

    since: float
    until: float
    stood_at: float
    paused_at: float
    resumed_at: float
    held_back_s: float


#: Pauses tried, as fractions of the smoothing window (1: a standing start; 0: fly on).
PAUSE_FRACTIONS = (1.0, 0.75, 0.5, 0.25, 0.0)


@dataclass(frozen=True)
class Resume:
    """How the formation resumes: a pause of `pause_s` inserted at mission time `at`, the
    clock set to `at + pause_s / 2`; `worst_error_m` is the tracking error it predicts."""

    at: float
    pause_s: float
    worst_error_m: float

    @property
    def clock_at(self) -> float:
        """The mission time the clock resumes from (the middle of the pause)."""
        return self.at + self.pause_s / 2


def resume_point(
    times: np.ndarray,
    targets: np.ndarray,
    positions: np.ndarray,
    velocities: np.ndarray,
    window_s: float,
    braking_mps2: float,
) -> Resume:
    """The resume that least disturbs the following UAVs.

    `times` (T,) increasing mission times the formation may resume at; `targets` (T, k, 2) the
    k following UAVs' virtual targets at those times under the profile flown (full speed);
    `positions` and `velocities` (k, 2) where those UAVs are and how they move now.
    """
    times = np.asarray(times, dtype=float)
    targets = np.asarray(targets, dtype=float)
    positions = np.asarray(positions, dtype=float)
    velocities = np.asarray(velocities, dtype=float)
    if len(times) < 2:
        return Resume(float(times[0]), 0.0, _worst(targets[:1], positions)[0])
    # each target's velocity at full speed (the profile flown), by central differences
    target_velocity = np.gradient(targets, times, axis=0)  # (T, k, 2)
    offset = positions[None] - targets  # (T, k, 2): where each UAV is from its target
    best: Resume | None = None
    for fraction in PAUSE_FRACTIONS:
        relative = velocities[None] - (1.0 - fraction) * target_velocity
        speed = np.linalg.norm(relative, axis=-1, keepdims=True)
        settled = offset + relative * speed / (2.0 * braking_mps2)
        error = np.maximum(np.linalg.norm(offset, axis=-1), np.linalg.norm(settled, axis=-1))
        worst = error.max(axis=1)  # (T,)
        index = int(np.argmin(worst))
        if best is None or worst[index] < best.worst_error_m - 1e-9:
            best = Resume(float(times[index]), fraction * window_s, float(worst[index]))
    assert best is not None
    return best


def _worst(targets: np.ndarray, positions: np.ndarray) -> np.ndarray:
    return np.linalg.norm(positions[None] - targets, axis=-1).max(axis=1)
