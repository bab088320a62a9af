"""The actuator around the PRSM: motor, gearbox, inertia, and how a run is configured.

Shared by the truth simulator (``prsm_health.scenes``) and the estimator
(``prsm_health.estimation``), so both convert between motor current and screw torque with the
same equations. The PRSM physics itself is in :mod:`prsm_health.physics`.

Sign conventions (SI, motor side unless named ``screw``):

- Positive motor rotation drives the screw at ``screw speed = motor speed / gear_ratio``.
- The axial load is a signed force ``F`` along the screw axis; ``F > 0`` resists positive
  rotation, so its screw torque is ``F L / 2 pi`` (L the lead). In the downhole cycle the
  traction load always resists the stroke, so ``F`` changes sign with the motor direction.
- Friction (PRSM and gearbox) opposes the screw speed.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from prsm_health.config import build_dataclass, build_each
from prsm_health.physics.errors import ParameterError
from prsm_health.physics.geometry import (
    Misalignment,
    require_ranges,
    require_real,
)
from prsm_health.physics.load_distribution import LoadingCase
from prsm_health.physics.meshing import smallest_misaligned_clearance
from prsm_health.physics.presets import PRESET_NAMES, Preset, load_preset

FloatArray = NDArray[np.float64]

#: The accepted range [low, high] of each drive-train parameter (:class:`DriveTrain` says why).
DRIVE_TRAIN_RANGES: dict[str, tuple[float, float]] = {
    "torque_constant_nm_per_a": (1e-4, 100.0),
    "gear_ratio": (1.0, 1e4),
    "gear_efficiency": (0.05, 1.0),
    "motor_inertia_kg_m2": (1e-10, 1e3),
    "screw_inertia_kg_m2": (1e-10, 1e3),
    "max_current_a": (1e-3, 1e5),
}
#: The accepted range of :attr:`Actuator.wear_acceleration`.
WEAR_ACCELERATION_RANGE = (1e-3, 1e9)


@dataclass(frozen=True, kw_only=True)
class DriveTrain:
    """Motor, gearbox and inertia between the motor current and the screw.

    torque_constant_nm_per_a: k_t, motor torque per ampere.
    gear_ratio: motor revolutions per screw revolution (1 = direct drive).
    gear_efficiency: eta_g of the gearbox when the motor drives it; its loss is a torque
        (1 - eta_g) / eta_g |T_screw| / gear_ratio that opposes the motion (so the motor
        supplies T_screw / (gear_ratio eta_g) when it drives, and the loss vanishes at rest).
    motor_inertia_kg_m2: rotor (and gearbox input) inertia, motor side.
    screw_inertia_kg_m2: screw, carrier and the reflected translating mass, screw side.
    max_current_a: the drive's current limit; larger measurements are out of range.

    Defaults: the downhole traction actuator of this project (a 48 V brushless motor with a
    5:1 planetary gearbox; paper 000 gives no drive-train data).

    Ranges (DRIVE_TRAIN_RANGES), physically generous; beyond them a ParameterError names the
    key (values far beyond them were accepted, then overflowed the estimator's arithmetic:
    an inertia of 1e200 kg m^2, an efficiency of 1e-300): k_t 1e-4 to 100 N m/A (a
    millimetre-size motor has about 1e-3, the largest torque motors tens); gear ratio 1 to
    1e4 (direct drive to the largest multi-stage reductions; no actuator speeds its screw up,
    and below 1 the carrier angle, the motor position times up to 1 / (2 G), could overflow);
    efficiency 0.05 to 1 (self-locking worm gears have 0.2 to 0.5); inertias 1e-10 to 1e3
    kg m^2 (a millimetre-size rotor has about 1e-9, a metre-size one up to about 10; the
    screw side includes the translating mass reflected by the lead, a tonne at a 0.1 m lead
    is 0.25); current limit 1 mA to 1e5 A (beyond the largest drives).
    """

    torque_constant_nm_per_a: float = 0.6
    gear_ratio: float = 5.0
    gear_efficiency: float = 0.95
    motor_inertia_kg_m2: float = 2.0e-4
    screw_inertia_kg_m2: float = 1.0e-3
    max_current_a: float = 60.0

    def __post_init__(self) -> None:
        require_ranges(self, "actuator.drive_train", DRIVE_TRAIN_RANGES)

    @property
    def inertia_at_motor_kg_m2(self) -> float:
        """Total inertia seen by the motor: J_m + J_s / G^2."""
        return self.motor_inertia_kg_m2 + self.screw_inertia_kg_m2 / self.gear_ratio**2

    def screw_speed_rad_s(self, motor_speed_rad_s: ArrayLike) -> FloatArray:
        """Screw speed from the motor speed, omega_s = omega_m / G."""
        return np.asarray(motor_speed_rad_s, dtype=np.float64) / self.gear_ratio

    def motor_torque_nm(
        self,
        screw_torque_nm: ArrayLike,
        screw_speed_rad_s: ArrayLike,
        motor_acceleration_rad_s2: ArrayLike = 0.0,
    ) -> FloatArray:
        """Motor torque that turns the screw against ``screw_torque_nm`` (load + friction).

        T_m = J_total alpha_m + T_s / G + sign(omega_s) (1 - eta_g) / eta_g |T_s| / G.
        """
        torque = np.asarray(screw_torque_nm, dtype=np.float64)
        direction = np.sign(np.asarray(screw_speed_rad_s, dtype=np.float64))
        loss = (1.0 - self.gear_efficiency) / self.gear_efficiency * np.abs(torque)
        inertia = self.inertia_at_motor_kg_m2 * np.asarray(motor_acceleration_rad_s2, float)
        return np.asarray(inertia + (torque + direction * loss) / self.gear_ratio, np.float64)

    def current_a(
        self,
        screw_torque_nm: ArrayLike,
        screw_speed_rad_s: ArrayLike,
        motor_acceleration_rad_s2: ArrayLike = 0.0,
    ) -> FloatArray:
        """Motor current for :meth:`motor_torque_nm`, i = T_m / k_t."""
        torque = self.motor_torque_nm(screw_torque_nm, screw_speed_rad_s, motor_acceleration_rad_s2)
        return np.asarray(torque / self.torque_constant_nm_per_a, dtype=np.float64)


def load_torque_nm(preset: Preset, axial_load_n: ArrayLike) -> FloatArray:
    """Screw torque of the signed axial load, F L / 2 pi (L the lead n_s p; paper 002 eq. 19)."""
    lead = preset.geometry.lead_m
    return np.asarray(np.asarray(axial_load_n, dtype=np.float64) * lead / (2.0 * math.pi))


@dataclass(frozen=True, kw_only=True)
class Actuator:
    """Everything known about the actuator being watched: PRSM, drive train, assembly.

    preset: the PRSM (a bundled preset name or a preset YAML path; see physics/presets).
    drive_train: motor, gearbox, inertia.
    misalignment: the screw misalignment of the assembly (paper 004), if known.
    case_forward, case_reverse: the loading case of paper 000 when the motor turns forward
        or in reverse (downhole cycle: step (c), motor forward, nut moves = case 2; step (f),
        motor reverse, nut fixed = case 1).
    wear_acceleration: hours of wear per hour of running. 1 for a real actuator; scenes
        raise it so that a short bag shows a measurable precision loss (bags/README.md; 4e6
        the most). Within WEAR_ACCELERATION_RANGE, 1e-3 to 1e9: a billion hours of wear per
        hour keeps a year's precision loss and its variance far from overflowing (1e200
        overflowed it).
    """

    preset: Preset
    drive_train: DriveTrain = field(default_factory=DriveTrain)
    misalignment: Misalignment = field(default_factory=Misalignment)
    case_forward: LoadingCase = LoadingCase.BOTH_COMPRESSION
    case_reverse: LoadingCase = LoadingCase.SCREW_TENSION_NUT_COMPRESSION
    wear_acceleration: float = 1.0

    def __post_init__(self) -> None:
        require_ranges(self, "actuator", {"wear_acceleration": WEAR_ACCELERATION_RANGE})
        _check_flanks_stay_apart(self.preset, self.misalignment)

    def loading_case(self, motor_speed_rad_s: float) -> LoadingCase:
        """The loading case for the motor's direction of rotation (forward at standstill)."""
        return self.case_reverse if motor_speed_rad_s < 0.0 else self.case_forward


_ACTUATOR_KEYS = {
    "preset",
    "drive_train",
    "misalignment_arcmin",
    "case_forward",
    "case_reverse",
    "wear_acceleration",
}


def _case(value: object, name: str) -> LoadingCase:
    if value not in (1, 2) or isinstance(value, bool):
        raise ParameterError(name, f"must be 1 or 2, got {value!r}")
    return LoadingCase(value)


def _misalignment(tilt: object) -> Misalignment:
    """``misalignment_arcmin: [x, y]``: two finite numbers (not bools), in arc minutes; every
    error names the key the user wrote, not Misalignment's fields in radians."""
    name = "actuator.misalignment_arcmin"
    if not (isinstance(tilt, list) and len(tilt) == 2):
        raise ParameterError(name, f"must be [x, y] in arc minutes, got {tilt!r}")
    x, y = (require_real(value, f"{name}[{i}]") for i, value in enumerate(tilt))
    try:
        return Misalignment.from_arcmin(x, y)
    except ParameterError as exc:  # beyond the small-angle limit
        raise ParameterError(name, f"{tilt!r} arc minutes: {exc}") from exc


def _check_flanks_stay_apart(preset: Preset, misalignment: Misalignment) -> None:
    """Refuse a misalignment that closes a screw-roller clearance at some carrier angle
    (:func:`~prsm_health.physics.meshing.smallest_misaligned_clearance`, exact over every
    angle): accepted, it raised a DomainError when the estimator or the simulator was built,
    not as a bad parameter (found by a review session; from 3 arc minutes on
    meng2022-misalignment and meng2021-fractal)."""
    if misalignment.is_aligned:
        return
    clearance_m, thread, angle_rad = smallest_misaligned_clearance(preset.geometry, misalignment)
    if clearance_m < 0.0:
        tilt = [
            round(math.degrees(t) * 60.0, 6)
            for t in (misalignment.tilt_x_rad, misalignment.tilt_y_rad)
        ]
        raise ParameterError(
            "actuator.misalignment_arcmin",
            f"{tilt} arc minutes is more than {preset.name}'s clearances allow: it closes the "
            f"screw-roller clearance of thread {thread + 1} to {clearance_m * 1e6:.3f} um where "
            f"a roller passes {math.degrees(angle_rad):.1f} deg; the flanks would overlap",
        )


def actuator_from_mapping(data: object) -> Actuator:
    """Build an :class:`Actuator` from the ``actuator:`` section of a scene or params file.

    Keys: preset (required), drive_train (mapping of :class:`DriveTrain` fields),
    misalignment_arcmin ([x, y]), case_forward, case_reverse (1 or 2), wear_acceleration.
    Unknown keys are refused with their name; every unknown key and every bad part (preset,
    drive train, misalignment, loading cases) is named in one error, wear_acceleration once
    they are good.
    """
    if not isinstance(data, dict):
        raise ParameterError("actuator", f"must be a mapping, got {type(data).__name__}")
    problems = [
        ParameterError(f"actuator.{key}", f"unknown key; allowed: {sorted(_ACTUATOR_KEYS)}")
        for key in sorted(set(data) - _ACTUATOR_KEYS)
    ]

    def preset() -> Preset:
        if "preset" not in data:
            raise ParameterError("actuator.preset", "missing")
        return load_preset(str(data["preset"]))

    parts: dict[str, Callable[[], object]] = {
        "preset": preset,
        "drive_train": lambda: build_dataclass(
            DriveTrain, data.get("drive_train"), "actuator.drive_train"
        ),
        "misalignment": lambda: _misalignment(data.get("misalignment_arcmin", [0.0, 0.0])),
        "case_forward": lambda: _case(data.get("case_forward", 2), "actuator.case_forward"),
        "case_reverse": lambda: _case(data.get("case_reverse", 1), "actuator.case_reverse"),
    }
    built = build_each(parts, problems)
    return Actuator(**built, wear_acceleration=data.get("wear_acceleration", 1.0))


def preset_beside_file(data: dict[str, Any], path: Path) -> dict[str, Any]:
    """A parsed scene or params file read from ``path``, with ``actuator.preset`` taken from
    that file's folder when it names a preset file by a relative path (as a file's references
    are read; not from the working directory, which would make the file mean something else
    in every folder it is used from). Bundled preset names, absolute paths and anything
    malformed are left as they are, for :func:`actuator_from_mapping` to judge."""
    section = data.get("actuator")
    if not isinstance(section, dict):
        return data
    relative = relative_preset_file(section.get("preset"))
    if relative is None:
        return data
    return {**data, "actuator": {**section, "preset": str(path.parent / relative)}}


def relative_preset_file(preset: object) -> Path | None:
    """The path of a preset file named by a relative path in an ``actuator.preset`` value;
    None for a bundled preset's name, an absolute path or anything else (which
    :func:`actuator_from_mapping` judges)."""
    if not isinstance(preset, str) or preset in PRESET_NAMES:
        return None
    path = Path(preset)
    return path if not path.is_absolute() and path.suffix in (".yaml", ".yml") else None
