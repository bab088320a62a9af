"""The drive's measurements of the motor: current, position, speed, time stamps, receive times.

- Current: the true motor current plus white Gaussian noise (``current_noise_std_a``),
  rounded to the ADC step ``current_quantum_a`` (0: not quantised).
- Position: an incremental encoder of ``encoder_counts_per_rev`` counts per motor revolution
  (the angle is floored to a whole count; 0: the exact angle).
- Speed: the drive's estimate, the encoder position differenced over one sample and low-pass
  filtered (first order, ``speed_filter_hz``), plus white noise ``speed_noise_std_rad_s``; with
  ``speed_filter_hz: 0`` the true motor speed plus that noise. Reported in steps of
  ``speed_quantum_rad_s`` (a drive's integer speed register; 0: not quantised).
- Header stamps: the sample time plus Gaussian jitter ``stamp_jitter_s``, truncated at
  +-0.4 sample periods (stamps stay in order unless a fault moves them).
- Receive time (the bag's log time): the recorder's clock, sample time + ``receive_latency_s``
  + half-normal extra delay of scale ``receive_jitter_s``; messages do not overtake each other
  (first in, first out), so receive times never decrease. The recorder's clock is not the
  sender's: a time-jump fault moves the header stamps only.

All noise comes from :mod:`prsm_health.scenes.noise` streams indexed by sample, and the few
carried values (last encoder reading, speed filter, last receive time) are handed from chunk
to chunk, so the measurements do not depend on the chunking.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter

from prsm_health.scenes.noise import NormalStream, Stream
from prsm_health.scenes.validation import integer, number
from prsm_health.signals import MotorSamples

FloatArray = NDArray[np.float64]

#: Stamp jitter is truncated at this fraction of the sample period.
JITTER_LIMIT = 0.4


@dataclass(frozen=True, kw_only=True)
class Sensors:
    """Sensor settings of a scene (see the module docstring; 0 switches a feature off)."""

    current_noise_std_a: float = 0.05
    current_quantum_a: float = 0.01
    encoder_counts_per_rev: int = 4096
    speed_filter_hz: float = 200.0
    speed_noise_std_rad_s: float = 0.1
    speed_quantum_rad_s: float = 0.001
    stamp_jitter_s: float = 20e-6
    receive_latency_s: float = 0.002
    receive_jitter_s: float = 0.0005

    def __post_init__(self) -> None:
        for name in (
            "current_noise_std_a",
            "current_quantum_a",
            "speed_filter_hz",
            "speed_noise_std_rad_s",
            "speed_quantum_rad_s",
            "stamp_jitter_s",
            "receive_latency_s",
            "receive_jitter_s",
        ):
            number(self, name, low=0.0)
        integer(self, "encoder_counts_per_rev", low=0)


@dataclass(frozen=True)
class SensorState:
    """Carried from chunk to chunk: last encoder reading, speed filter, last receive time."""

    position_rad: float
    speed_filter: FloatArray
    receive_time_s: float


class SensorModel:
    """Turns true motor signals into measurements (see the module docstring)."""

    def __init__(self, sensors: Sensors, period_s: float, seed: int) -> None:
        self._sensors = sensors
        self._period_s = period_s
        self._current_noise = NormalStream(seed, Stream.CURRENT_NOISE)
        self._speed_noise = NormalStream(seed, Stream.SPEED_NOISE)
        self._jitter = NormalStream(seed, Stream.STAMP_JITTER)
        self._receive = NormalStream(seed, Stream.RECEIVE_JITTER)
        smoothing = math.exp(-2.0 * math.pi * sensors.speed_filter_hz * period_s)
        self._filter_b = np.array([1.0 - smoothing])
        self._filter_a = np.array([1.0, -smoothing])

    def _encoder(self, angle_rad: FloatArray) -> FloatArray:
        counts = self._sensors.encoder_counts_per_rev
        if counts == 0:
            return angle_rad
        step = 2.0 * math.pi / counts
        return np.asarray(np.floor(angle_rad / step) * step, dtype=np.float64)

    def initial_state(self, previous_angle_rad: float, motor_speed_rad_s: float) -> SensorState:
        """Steady state before the first sample: encoder at ``previous_angle_rad``, filter settled
        at ``motor_speed_rad_s``."""
        before = self._encoder(np.array([previous_angle_rad]))
        return SensorState(
            position_rad=float(before[0]),
            speed_filter=-self._filter_a[1:] * motor_speed_rad_s,
            receive_time_s=-math.inf,
        )

    def measure(
        self,
        first_sample: int,
        time_s: FloatArray,
        current_a: FloatArray,
        motor_speed_rad_s: FloatArray,
        motor_angle_rad: FloatArray,
        state: SensorState,
    ) -> tuple[MotorSamples, FloatArray, SensorState]:
        """Measurements of samples first_sample, first_sample + 1, ...; and the next state.

        Returns the samples (header stamps as sent), their receive times and the state.
        """
        s = self._sensors
        start, stop = first_sample, first_sample + len(time_s)
        current = current_a + s.current_noise_std_a * self._current_noise.take(start, stop)
        if s.current_quantum_a > 0.0:
            current = np.round(current / s.current_quantum_a) * s.current_quantum_a
        position = self._encoder(motor_angle_rad)
        speed_filter = state.speed_filter
        if s.speed_filter_hz > 0.0:
            previous = np.concatenate(([state.position_rad], position[:-1]))
            raw = (position - previous) / self._period_s
            speed, speed_filter = lfilter(
                self._filter_b, self._filter_a, raw, zi=state.speed_filter
            )
        else:
            speed = motor_speed_rad_s
        speed = speed + s.speed_noise_std_rad_s * self._speed_noise.take(start, stop)
        if s.speed_quantum_rad_s > 0.0:
            speed = np.round(speed / s.speed_quantum_rad_s) * s.speed_quantum_rad_s
        limit = JITTER_LIMIT * self._period_s
        jitter = np.clip(s.stamp_jitter_s * self._jitter.take(start, stop), -limit, limit)
        delay = s.receive_latency_s + s.receive_jitter_s * np.abs(self._receive.take(start, stop))
        receive = np.maximum.accumulate(np.concatenate(([state.receive_time_s], time_s + delay)))[
            1:
        ]
        samples = MotorSamples(
            stamp_s=time_s + jitter,
            current_a=np.asarray(current, dtype=np.float64),
            speed_rad_s=np.asarray(speed, dtype=np.float64),
            position_rad=position,
        )
        if len(time_s) == 0:
            return samples, receive, state
        next_state = SensorState(float(position[-1]), speed_filter, float(receive[-1]))
        return samples, receive, next_state
