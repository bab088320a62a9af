"""What a scene asks of the actuator: the screw speed reference and the axial and radial loads.

Signs follow :mod:`prsm_health.actuator`: a positive speed is forward motor rotation, the
signed axial load F > 0 resists forward rotation. Every profile gives, at the sample times,
the screw speed reference, the signed axial load (before load noise) and the direction (+1
forward, -1 reverse) whose loading case applies (``Actuator.case_forward/case_reverse``); the
direction of the last motion is held at standstill.

Profiles (the ``type`` of a scene's ``profile:`` section):

- ``downhole_cycle``: the telescopic robot of paper 000 (section 2.2, steps b-h). Support
  steps (b, d, e, g, h) at standstill, each ``support_s`` long, and two strokes of
  ``stroke_m``: (c) motor forward, the nut drives the right body forward, and (f) motor in
  reverse with the nut fixed, the screw drawing the body. The traction load resists each
  stroke (F = +level in (c), -level in (f)), ramps up smoothly over ``load_ramp_s`` at the
  stroke start and down at its end; the speed is a trapezoid with ``accel_s`` ramps. Speed
  and load level are drawn per stroke, uniformly in their ranges, from the scene seed.
- ``hold``: a forward move, a standstill holding ``hold_load_n``, a return move (in reverse by
  default, where a positive load then assists the motion: back-driving).
- ``constant``, ``ramp``, ``sine``: simple references for tests.

Radial load (``radial_load:``): ``constant``, or ``wall``, a borehole-wall contact level that
varies smoothly between ``min_n`` and ``max_n`` (three sinusoids of periods ``period_s`` times
1, 0.618 and 0.382 with phases drawn from the seed). Axial load noise (``load_noise:``) is a
first-order low-pass (``bandwidth_hz``) Gaussian process with relative standard deviation
``relative_std``, multiplying the load (applied by the simulator).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from prsm_health.physics.errors import ParameterError
from prsm_health.scenes.noise import Stream, scene_generator
from prsm_health.scenes.validation import flag, level_or_range, number, section

FloatArray = NDArray[np.float64]
DirectionArray = NDArray[np.int8]

RPM_TO_RAD_S = 2.0 * math.pi / 60.0


@dataclass(frozen=True)
class Reference:
    """Profile values at the sample times (screw side, SI)."""

    speed_rad_s: FloatArray
    axial_load_n: FloatArray
    direction: DirectionArray


def _smoothstep(x: FloatArray) -> FloatArray:
    """Raised-cosine ramp from 0 (x <= 0) to 1 (x >= 1)."""
    return np.asarray(0.5 - 0.5 * np.cos(math.pi * np.clip(x, 0.0, 1.0)), dtype=np.float64)


@dataclass(frozen=True)
class _Segments:
    """Motion segments: a trapezoidal speed and a smoothly ramped load each."""

    start_s: FloatArray
    duration_s: FloatArray
    speed_rad_s: FloatArray  # signed plateau speed
    load_n: FloatArray  # signed plateau load
    direction: DirectionArray
    accel_s: float
    load_ramp_s: float

    def reference(self, time_s: FloatArray) -> Reference:
        index = np.searchsorted(self.start_s, time_s, side="right") - 1
        safe = np.maximum(index, 0)
        elapsed = time_s - self.start_s[safe]
        length = self.duration_s[safe]
        inside = (index >= 0) & (elapsed < length)
        edge = np.minimum(elapsed, length - elapsed)  # time from the nearer segment end
        speed = self.speed_rad_s[safe] * np.clip(edge / self.accel_s, 0.0, 1.0)
        load = self.load_n[safe] * _smoothstep(edge / self.load_ramp_s)
        return Reference(
            speed_rad_s=np.where(inside, speed, 0.0),
            axial_load_n=np.where(inside, load, 0.0),
            direction=np.where(index >= 0, self.direction[safe], 1).astype(np.int8),
        )


def _segments(
    rows: list[tuple[float, float, float, float, int]], accel: float, ramp: float
) -> _Segments:
    start, duration, speed, load, direction = (np.array(c) for c in zip(*rows, strict=True))
    return _Segments(
        start_s=start.astype(np.float64),
        duration_s=duration.astype(np.float64),
        speed_rad_s=speed.astype(np.float64),
        load_n=load.astype(np.float64),
        direction=direction.astype(np.int8),
        accel_s=accel,
        load_ramp_s=ramp,
    )


@dataclass(frozen=True, kw_only=True)
class DownholeCycle:
    """The downhole robot's cycle (paper 000 steps b-h); see the module docstring.

    stroke_m: nut travel per stroke. speed_rpm: screw speed, a level or [min, max] drawn per
    stroke (000 section 5.4: 100-700 rpm). traction_load_n: axial load level, a number or
    [min, max] drawn per stroke (000: 10-55 kN). support_s: each support step at standstill.
    accel_s: speed ramp time. load_ramp_s: load ramp time at each stroke end.
    """

    stroke_m: float = 0.12
    speed_rpm: tuple[float, float] = (250.0, 450.0)
    traction_load_n: tuple[float, float] = (10_000.0, 55_000.0)
    support_s: float = 2.0
    accel_s: float = 0.25
    load_ramp_s: float = 0.5

    def __post_init__(self) -> None:
        number(self, "stroke_m", low=0.0, open_low=True)
        level_or_range(self, "speed_rpm", low=0.0, open_low=True)
        level_or_range(self, "traction_load_n", low=0.0)
        number(self, "support_s", low=0.0)
        number(self, "accel_s", low=0.0, open_low=True)
        number(self, "load_ramp_s", low=0.0, open_low=True)

    def _stroke_s(self, speed_rpm: float, lead_m: float) -> float:
        travel_speed = speed_rpm * RPM_TO_RAD_S * lead_m / (2.0 * math.pi)
        return float(self.stroke_m / travel_speed + self.accel_s)

    def check(self, lead_m: float) -> None:
        """Refuse strokes too short for their speed and load ramps (names the field)."""
        shortest = self._stroke_s(self.speed_rpm[1], lead_m)
        needed = 2.0 * max(self.accel_s, self.load_ramp_s)
        if shortest < needed:
            raise ParameterError(
                "stroke_m",
                f"the fastest stroke lasts {shortest:.3g} s, shorter than its two ramps "
                f"({needed:.3g} s): lengthen the stroke or shorten accel_s / load_ramp_s",
            )

    def segments(self, duration_s: float, lead_m: float, seed: int) -> _Segments:
        """The strokes up to ``duration_s``: (c) forward, then d + e, (f) reverse, g + h + b."""
        draw = scene_generator(seed, Stream.SCHEDULE)
        rows: list[tuple[float, float, float, float, int]] = []
        time = self.support_s  # step (b) first
        while time < duration_s or not rows:  # at least one cycle
            for direction, gap in ((1, 2.0 * self.support_s), (-1, 3.0 * self.support_s)):
                speed_rpm = float(draw.uniform(*self.speed_rpm))
                load = float(draw.uniform(*self.traction_load_n))
                length = self._stroke_s(speed_rpm, lead_m)
                rows.append(
                    (
                        time,
                        length,
                        direction * speed_rpm * RPM_TO_RAD_S,
                        direction * load,
                        direction,
                    )
                )
                time += length + gap
        return _segments(rows, self.accel_s, self.load_ramp_s)


@dataclass(frozen=True, kw_only=True)
class HoldProfile:
    """Move forward, hold a load at standstill, move back (``stationary-hold``).

    start_s: standstill before the first move. speed_rpm: first move's screw speed (> 0).
    return_speed_rpm: the return move's (signed; negative = reverse). move_s: length of each
    move. axial_load_n: signed load during the moves. hold_load_n: signed load held.
    hold_s: standstill. accel_s, load_ramp_s: speed and load ramp times.
    """

    start_s: float = 1.0
    speed_rpm: float = 300.0
    return_speed_rpm: float = -300.0
    move_s: float = 5.0
    axial_load_n: float = 15_000.0
    hold_load_n: float = 50_000.0
    hold_s: float = 30.0
    accel_s: float = 0.25
    load_ramp_s: float = 1.0

    def __post_init__(self) -> None:
        number(self, "start_s", low=0.0)
        number(self, "speed_rpm", low=0.0, open_low=True)
        if number(self, "return_speed_rpm") == 0.0:
            raise ParameterError("return_speed_rpm", "must not be 0")
        number(self, "axial_load_n")
        number(self, "hold_load_n")
        number(self, "accel_s", low=0.0, open_low=True)
        number(self, "load_ramp_s", low=0.0, open_low=True)
        ramps = 2.0 * max(self.accel_s, self.load_ramp_s)
        number(self, "move_s", low=ramps)
        number(self, "hold_s", low=2.0 * self.load_ramp_s)

    def segments(self) -> _Segments:
        back = 1 if self.return_speed_rpm > 0.0 else -1
        second = self.start_s + self.move_s
        third = second + self.hold_s
        rows = [
            (self.start_s, self.move_s, self.speed_rpm * RPM_TO_RAD_S, self.axial_load_n, 1),
            (second, self.hold_s, 0.0, self.hold_load_n, 1),
            (third, self.move_s, self.return_speed_rpm * RPM_TO_RAD_S, self.axial_load_n, back),
        ]
        return _segments(rows, self.accel_s, self.load_ramp_s)


def _direction(speed: FloatArray) -> DirectionArray:
    return np.where(speed < 0.0, -1, 1).astype(np.int8)


@dataclass(frozen=True, kw_only=True)
class ConstantProfile:
    """Constant screw speed (signed) and signed axial load, steady from t = 0."""

    speed_rpm: float = 300.0
    axial_load_n: float = 20_000.0

    def __post_init__(self) -> None:
        number(self, "speed_rpm")
        number(self, "axial_load_n")

    def reference(self, time_s: FloatArray) -> Reference:
        speed = np.full(time_s.shape, self.speed_rpm * RPM_TO_RAD_S)
        return Reference(speed, np.full(time_s.shape, self.axial_load_n), _direction(speed))


@dataclass(frozen=True, kw_only=True)
class RampProfile:
    """Speed and signed load linear from their start to their end values over ``ramp_s``."""

    speed_start_rpm: float = 0.0
    speed_end_rpm: float = 500.0
    axial_load_start_n: float = 0.0
    axial_load_end_n: float = 40_000.0
    ramp_s: float = 10.0

    def __post_init__(self) -> None:
        for name in ("speed_start_rpm", "speed_end_rpm", "axial_load_start_n", "axial_load_end_n"):
            number(self, name)
        number(self, "ramp_s", low=0.0, open_low=True)

    def reference(self, time_s: FloatArray) -> Reference:
        fraction = np.clip(time_s / self.ramp_s, 0.0, 1.0)
        speed_rpm = self.speed_start_rpm + (self.speed_end_rpm - self.speed_start_rpm) * fraction
        load = (
            self.axial_load_start_n + (self.axial_load_end_n - self.axial_load_start_n) * fraction
        )
        speed = speed_rpm * RPM_TO_RAD_S
        return Reference(speed, np.asarray(load, dtype=np.float64), _direction(speed))


@dataclass(frozen=True, kw_only=True)
class SineProfile:
    """Sinusoidal screw speed; an axial load of ``axial_load_n`` resisting the reference speed
    (it changes sign at each reversal, as the friction of a body dragged along a wall), or
    with ``resisting`` false the same load all the time (as gravity on a vertical axis: it
    resists the forward strokes and drives the reverse ones)."""

    speed_amplitude_rpm: float = 300.0
    speed_offset_rpm: float = 0.0
    period_s: float = 4.0
    axial_load_n: float = 20_000.0
    resisting: bool = True

    def __post_init__(self) -> None:
        number(self, "speed_amplitude_rpm", low=0.0)
        number(self, "speed_offset_rpm")
        number(self, "period_s", low=0.0, open_low=True)
        number(self, "axial_load_n", low=0.0)
        flag(self, "resisting")

    def reference(self, time_s: FloatArray) -> Reference:
        phase = 2.0 * math.pi * time_s / self.period_s
        speed = (self.speed_offset_rpm + self.speed_amplitude_rpm * np.sin(phase)) * RPM_TO_RAD_S
        direction = _direction(speed)
        sign = direction if self.resisting else np.ones_like(direction)
        load = np.asarray(sign * self.axial_load_n, dtype=np.float64)
        return Reference(speed, load, direction)


Profile = DownholeCycle | HoldProfile | ConstantProfile | RampProfile | SineProfile

PROFILE_TYPES: dict[str, type[Profile]] = {
    "downhole_cycle": DownholeCycle,
    "hold": HoldProfile,
    "constant": ConstantProfile,
    "ramp": RampProfile,
    "sine": SineProfile,
}


def _typed_section(data: object, name: str, types: dict[str, type[Any]]) -> Any:
    """The section built by the class its ``type`` key names."""
    if not isinstance(data, dict):
        raise ParameterError(name, f"must be a mapping, got {type(data).__name__}")
    kind = data.get("type")
    if kind not in types:
        raise ParameterError(f"{name}.type", f"must be one of {', '.join(types)}, got {kind!r}")
    return section(types[kind], {k: v for k, v in data.items() if k != "type"}, name)


def profile_from_mapping(data: object, name: str = "profile") -> Profile:
    """The profile of a scene's ``profile:`` section (``type`` chooses the class)."""
    profile: Profile = _typed_section(data, name, PROFILE_TYPES)
    return profile


@dataclass(frozen=True, kw_only=True)
class ConstantRadial:
    """A constant radial load [N]."""

    value_n: float = 0.0

    def __post_init__(self) -> None:
        number(self, "value_n", low=0.0)

    @property
    def peak_n(self) -> float:
        """Largest value of the profile."""
        return self.value_n

    def values(self, time_s: FloatArray, seed: int) -> FloatArray:
        """The radial load at ``time_s`` (the seed is not used)."""
        return np.full(time_s.shape, self.value_n)


#: Periods of the wall profile's three sinusoids relative to ``period_s`` (golden ratio steps).
WALL_PERIOD_RATIOS = (1.0, 0.618, 0.382)


@dataclass(frozen=True, kw_only=True)
class WallContact:
    """Borehole-wall contact: a radial load varying smoothly in [min_n, max_n]."""

    min_n: float = 0.0
    max_n: float = 8_000.0
    period_s: float = 7.0

    def __post_init__(self) -> None:
        number(self, "min_n", low=0.0)
        number(self, "max_n", low=self.min_n)
        number(self, "period_s", low=0.0, open_low=True)

    @property
    def peak_n(self) -> float:
        """Largest value of the profile."""
        return self.max_n

    def values(self, time_s: FloatArray, seed: int) -> FloatArray:
        """The radial load at ``time_s``; the sinusoids' phases are drawn from ``seed``."""
        phases = scene_generator(seed, Stream.WALL).uniform(0.0, 2.0 * math.pi, 3)
        wave = np.zeros(time_s.shape)
        for ratio, phase in zip(WALL_PERIOD_RATIOS, phases, strict=True):
            wave += np.sin(2.0 * math.pi * time_s / (ratio * self.period_s) + phase)
        level = 0.5 + wave / (2.0 * len(WALL_PERIOD_RATIOS))
        return np.asarray(self.min_n + (self.max_n - self.min_n) * level, dtype=np.float64)


RadialLoad = ConstantRadial | WallContact

RADIAL_TYPES: dict[str, type[RadialLoad]] = {"constant": ConstantRadial, "wall": WallContact}


def radial_load_from_mapping(data: object, name: str = "radial_load") -> RadialLoad:
    """The radial load of a scene's ``radial_load:`` section (none: a constant 0 N)."""
    if data is None:
        return ConstantRadial()
    radial: RadialLoad = _typed_section(data, name, RADIAL_TYPES)
    return radial


@dataclass(frozen=True, kw_only=True)
class LoadNoise:
    """Coloured noise on the axial load: relative std and first-order bandwidth [Hz]."""

    relative_std: float = 0.0
    bandwidth_hz: float = 0.2

    def __post_init__(self) -> None:
        number(self, "relative_std", low=0.0, high=0.2)
        number(self, "bandwidth_hz", low=0.0, open_low=True)
