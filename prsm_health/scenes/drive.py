"""The drive's motion: speed loop, screw angle, and the holding torque at standstill (stiction).

Speed loop. The screw speed follows the profile's reference through a critically damped
second-order closed loop, omega / omega_ref = w_n^2 / (s + w_n)^2 with w_n = 2 pi
``bandwidth_hz``, discretised exactly (zero-order hold) and run with ``scipy.signal.lfilter``
carrying its state from chunk to chunk; the acceleration is the loop's state derivative, not
a finite difference. The load does not disturb the speed (an ideal current loop with enough
margin; the simulator refuses currents above the drive's limit). The loop's response to a
reference that comes to rest never reaches zero; once the reference is zero and the speed
below ``standstill_speed_rad_s`` the screw is at rest (speed and acceleration exactly 0),
which is where stiction takes over. The screw angle integrates the speed (trapezoidal rule).

Stiction. At rest the friction can take any value within +-M_static, the breakaway torque
(paper 002's friction at omega_s = 0: the rolling losses of healthy rollers plus the sliding
torque of jammed ones). The drive's screw torque holds its last value, clamped into
[T_load - M_static, T_load + M_static] as the load changes, so the friction T_drive - T_load
never leaves its band: T_k = clip(T_(k-1), T_load,k - M_static,k, T_load,k + M_static,k).
In motion T_k = T_load + sign(omega) M_kinetic (a degenerate clamp). :func:`clamp_recursion`
runs this recursion vectorised (a prefix scan of clamp compositions, exact: only min/max).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.signal import cont2discrete, lfilter, lfilter_zi, ss2tf

from prsm_health.scenes.validation import number

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, kw_only=True)
class SpeedLoop:
    """The closed speed loop: bandwidth [Hz] and the speed below which the screw is at rest."""

    bandwidth_hz: float = 25.0
    standstill_speed_rad_s: float = 1e-3

    def __post_init__(self) -> None:
        number(self, "bandwidth_hz", low=0.0, open_low=True)
        number(self, "standstill_speed_rad_s", low=0.0, open_low=True)


@dataclass(frozen=True)
class MotionState:
    """What a chunk hands to the next: filter states, last speed and screw angle."""

    speed_filter: FloatArray
    accel_filter: FloatArray
    speed_rad_s: float
    screw_angle_rad: float


@dataclass(frozen=True)
class Motion:
    """Screw speed, acceleration and angle of a chunk (SI)."""

    speed_rad_s: FloatArray
    acceleration_rad_s2: FloatArray
    screw_angle_rad: FloatArray


class Drive:
    """The speed loop of :class:`SpeedLoop` at a sample period (see the module docstring)."""

    def __init__(self, loop: SpeedLoop, period_s: float) -> None:
        w_n = 2.0 * math.pi * loop.bandwidth_hz
        a = np.array([[0.0, 1.0], [-(w_n**2), -2.0 * w_n]])
        b = np.array([[0.0], [w_n**2]])
        ad, bd, cd, dd, _ = cont2discrete((a, b, np.eye(2), np.zeros((2, 1))), period_s, "zoh")
        numerators, denominator = ss2tf(ad, bd, cd, dd)
        self._speed_b, self._accel_b = numerators[0], numerators[1]
        self._a = denominator
        self._period_s = period_s
        self._rest = loop.standstill_speed_rad_s

    def initial_state(self, speed_rad_s: float) -> MotionState:
        """Steady state at the reference's first value (speed and its reference equal)."""
        return MotionState(
            speed_filter=lfilter_zi(self._speed_b, self._a) * speed_rad_s,
            accel_filter=lfilter_zi(self._accel_b, self._a) * speed_rad_s,
            speed_rad_s=speed_rad_s,
            screw_angle_rad=0.0,
        )

    def run(self, reference_rad_s: FloatArray, state: MotionState) -> tuple[Motion, MotionState]:
        """The motion for a chunk of speed references, and the state after it."""
        speed, speed_filter = lfilter(
            self._speed_b, self._a, reference_rad_s, zi=state.speed_filter
        )
        accel, accel_filter = lfilter(
            self._accel_b, self._a, reference_rad_s, zi=state.accel_filter
        )
        at_rest = (reference_rad_s == 0.0) & (np.abs(speed) < self._rest)
        speed = np.where(at_rest, 0.0, speed)
        accel = np.where(at_rest, 0.0, accel)
        previous = np.concatenate(([state.speed_rad_s], speed[:-1]))
        steps = (0.5 * self._period_s) * (speed + previous)
        angle = np.cumsum(np.concatenate(([state.screw_angle_rad], steps)))[1:]
        motion = Motion(
            speed_rad_s=np.asarray(speed, dtype=np.float64),
            acceleration_rad_s2=np.asarray(accel, dtype=np.float64),
            screw_angle_rad=angle,
        )
        if len(speed) == 0:
            return motion, state
        return motion, MotionState(speed_filter, accel_filter, float(speed[-1]), float(angle[-1]))


def clamp_recursion(lower: FloatArray, upper: FloatArray, initial: float) -> FloatArray:
    """y_k = clip(y_(k-1), lower_k, upper_k), y_(-1) = initial, for lower <= upper.

    A composition of clamps is a clamp: clip(clip(x, L1, U1), L2, U2) = clip(x, clip(L1, L2,
    U2), clip(U1, L2, U2)). The prefix compositions are built by doubling (Hillis-Steele),
    log2(n) vectorised steps; only min/max are used, so the result is exact (and the same
    whatever the chunking of the series).
    """
    low, high = lower.copy(), upper.copy()
    shift = 1
    while shift < len(low):
        earlier_low, earlier_high = low[:-shift], high[:-shift]
        now_low, now_high = low[shift:], high[shift:]
        low[shift:], high[shift:] = (
            np.clip(earlier_low, now_low, now_high),
            np.clip(earlier_high, now_low, now_high),
        )
        shift *= 2
    return np.asarray(np.clip(initial, low, high), dtype=np.float64)
