"""Sensor faults injected into the measurements (never into the truth).

A scene's ``sensor_faults:`` section lists, each with its times (s from the scene start; a
time falls on the sample round(time * rate)):

- ``dropouts``: {start_s, duration_s}: those samples are not published at all;
- ``nonfinite``: {time_s, field, value: .nan | .inf | -.inf, samples}: a field replaced;
- ``spikes``: {time_s, field, value}: ``value`` added to one sample of a field;
- ``stuck``: {start_s, duration_s, field}: a field repeats its value of the segment's first
  sample;
- ``time_jumps``: {time_s, jump_s}: from that sample on every header stamp is shifted by
  ``jump_s`` (negative: the sender's clock jumps backwards; the bag's receive times do not).

``field`` is ``current_a``, ``speed_rad_s``, ``position_rad`` or ``all``. Stuck runs apply
first, then spikes, non-finite values, time jumps and dropouts. The value a stuck run repeats
is carried across chunks, so the result does not depend on the chunking.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

from prsm_health.physics.errors import ParameterError
from prsm_health.scenes.validation import integer, items, number, section
from prsm_health.signals import MotorSamples

FloatArray = NDArray[np.float64]

T = TypeVar("T")

FIELDS = ("current_a", "speed_rad_s", "position_rad")


def _field(obj: object) -> tuple[str, ...]:
    name = obj.field  # type: ignore[attr-defined]
    if name == "all":
        return FIELDS
    if name not in FIELDS:
        raise ParameterError("field", f"must be one of {', '.join(FIELDS)} or all, got {name!r}")
    return (name,)


@dataclass(frozen=True, kw_only=True)
class Dropout:
    """No samples published in [start_s, start_s + duration_s)."""

    start_s: float
    duration_s: float

    def __post_init__(self) -> None:
        number(self, "start_s", low=0.0)
        number(self, "duration_s", low=0.0, open_low=True)


@dataclass(frozen=True, kw_only=True)
class NonFinite:
    """``samples`` samples of ``field`` from ``time_s`` replaced by NaN or +-inf."""

    time_s: float
    field: str
    value: float
    samples: int = 1

    def __post_init__(self) -> None:
        number(self, "time_s", low=0.0)
        _field(self)
        if not (isinstance(self.value, float) and not math.isfinite(self.value)):
            raise ParameterError("value", f"must be .nan, .inf or -.inf, got {self.value!r}")
        integer(self, "samples", low=1)


@dataclass(frozen=True, kw_only=True)
class Spike:
    """``value`` added to ``field`` at ``time_s``."""

    time_s: float
    field: str
    value: float

    def __post_init__(self) -> None:
        number(self, "time_s", low=0.0)
        _field(self)
        number(self, "value")


@dataclass(frozen=True, kw_only=True)
class Stuck:
    """``field`` frozen at its value of the first sample of [start_s, start_s + duration_s)."""

    start_s: float
    duration_s: float
    field: str

    def __post_init__(self) -> None:
        number(self, "start_s", low=0.0)
        number(self, "duration_s", low=0.0, open_low=True)
        _field(self)


@dataclass(frozen=True, kw_only=True)
class TimeJump:
    """Header stamps shifted by ``jump_s`` from ``time_s`` on."""

    time_s: float
    jump_s: float

    def __post_init__(self) -> None:
        number(self, "time_s", low=0.0)
        if number(self, "jump_s") == 0.0:
            raise ParameterError("jump_s", "must not be 0")


@dataclass(frozen=True, kw_only=True)
class SensorFaults:
    """All faults of a scene (see the module docstring)."""

    dropouts: tuple[Dropout, ...] = ()
    nonfinite: tuple[NonFinite, ...] = ()
    spikes: tuple[Spike, ...] = ()
    stuck: tuple[Stuck, ...] = ()
    time_jumps: tuple[TimeJump, ...] = ()


_FAULT_KEYS = tuple(f.name for f in fields(SensorFaults))


def sensor_faults_from_mapping(data: object, name: str = "sensor_faults") -> SensorFaults:
    """The faults of a scene's ``sensor_faults:`` section, each list item validated by name."""
    if data is None:
        return SensorFaults()
    if not isinstance(data, dict):
        raise ParameterError(name, f"must be a mapping, got {type(data).__name__}")
    unknown = sorted(set(data) - set(_FAULT_KEYS))
    if unknown:
        raise ParameterError(
            f"{name}.{unknown[0]}", f"unknown key; allowed: {', '.join(_FAULT_KEYS)}"
        )

    def parsed(key: str, cls: type[T]) -> tuple[T, ...]:
        listed = items(data.get(key), f"{name}.{key}")
        return tuple(section(cls, item, f"{name}.{key}[{i}]") for i, item in enumerate(listed))

    return SensorFaults(
        dropouts=parsed("dropouts", Dropout),
        nonfinite=parsed("nonfinite", NonFinite),
        spikes=parsed("spikes", Spike),
        stuck=parsed("stuck", Stuck),
        time_jumps=parsed("time_jumps", TimeJump),
    )


class FaultInjector:
    """Applies :class:`SensorFaults` to chunks of measurements at a sample rate."""

    def __init__(self, faults: SensorFaults, rate_hz: float) -> None:
        self._faults = faults
        self._rate_hz = rate_hz
        self._stuck_values: dict[tuple[int, str], float] = {}

    def _sample(self, time_s: float) -> int:
        return round(time_s * self._rate_hz)

    def apply(
        self, first_sample: int, samples: MotorSamples, receive_time_s: FloatArray
    ) -> tuple[MotorSamples, FloatArray]:
        """The faulty measurements of samples first_sample, ... and their receive times.

        Call chunk after chunk in order (stuck values carry over).
        """
        count = len(samples)
        index = np.arange(first_sample, first_sample + count)
        values = {name: np.array(getattr(samples, name)) for name in FIELDS}
        for number_, fault in enumerate(self._faults.stuck):
            begin = self._sample(fault.start_s)
            end = begin + max(1, self._sample(fault.duration_s))
            for name in _field(fault):
                key = (number_, name)
                if first_sample <= begin < first_sample + count:
                    self._stuck_values[key] = float(values[name][begin - first_sample])
                if key in self._stuck_values:
                    inside = (index >= begin) & (index < end)
                    values[name][inside] = self._stuck_values[key]
        for spike in self._faults.spikes:
            at = self._sample(spike.time_s) - first_sample
            if 0 <= at < count:
                for name in _field(spike):
                    values[name][at] += spike.value
        for bad in self._faults.nonfinite:
            begin = self._sample(bad.time_s)
            inside = (index >= begin) & (index < begin + bad.samples)
            for name in _field(bad):
                values[name][inside] = bad.value
        stamps = np.array(samples.stamp_s)
        for jump in self._faults.time_jumps:
            stamps[index >= self._sample(jump.time_s)] += jump.jump_s
        keep = np.ones(count, dtype=bool)
        for dropout in self._faults.dropouts:
            begin = self._sample(dropout.start_s)
            keep &= ~((index >= begin) & (index < begin + self._sample(dropout.duration_s)))
        faulty = MotorSamples(
            stamp_s=stamps[keep],
            current_a=values["current_a"][keep],
            speed_rad_s=values["speed_rad_s"][keep],
            position_rad=values["position_rad"][keep],
        )
        return faulty, receive_time_s[keep]
