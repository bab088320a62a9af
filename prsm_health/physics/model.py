"""The full PRSM model at one operating point: loads, friction, efficiency, wear, fatigue.

This is the chain the papers run in sequence: meshing clearances (004 eq. 1-12) -> thread
load distribution (000 eq. 7-25, 004 eq. 14-22) -> friction torque and efficiency (002
eq. 2-19) -> slip speed and precision-loss rate (001 eq. 30-38, 004 eq. 32-35) -> fatigue life
(000 eq. 29). The CLI, the truth simulator and the surrogate tables all call
:func:`evaluate`, so there is one place where the pieces are wired together.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from prsm_health.physics.errors import ParameterError
from prsm_health.physics.fatigue import fatigue_life_h
from prsm_health.physics.friction import FrictionTorque, efficiency, friction_torque
from prsm_health.physics.geometry import Misalignment, require
from prsm_health.physics.load_distribution import (
    LoadDistribution,
    LoadingCase,
    solve_load_distribution,
)
from prsm_health.physics.meshing import Meshing, meshing, slip_speed_m_s
from prsm_health.physics.presets import Preset
from prsm_health.physics.wear import precision_loss_rate_m_per_s


@dataclass(frozen=True, kw_only=True)
class OperatingPoint:
    """Where the actuator is: loads, screw speed, faults and assembly state (SI)."""

    axial_load_n: float
    radial_load_n: float = 0.0
    screw_speed_rad_s: float = 0.0
    jammed_rollers: int = 0
    misalignment: Misalignment = field(default_factory=Misalignment)
    case: LoadingCase = LoadingCase.SCREW_TENSION_NUT_COMPRESSION
    carrier_angle_rad: float = 0.0
    elastic_errors: bool = False

    def __post_init__(self) -> None:
        for name in ("axial_load_n", "radial_load_n", "screw_speed_rad_s", "carrier_angle_rad"):
            value = getattr(self, name)
            require(math.isfinite(value), name, f"must be finite, got {value!r}")
        require(self.axial_load_n >= 0.0, "axial_load_n", "must be >= 0")
        require(self.radial_load_n >= 0.0, "radial_load_n", "must be >= 0")
        require(self.jammed_rollers >= 0, "jammed_rollers", "must be >= 0")


@dataclass(frozen=True)
class ModelResult:
    """Everything the model says about one operating point."""

    point: OperatingPoint
    loads: LoadDistribution
    meshing: Meshing
    friction: FrictionTorque
    efficiency: float
    precision_loss_rate_m_per_s: float
    fatigue_life_h: float


def evaluate(preset: Preset, point: OperatingPoint) -> ModelResult:
    """Run the whole physics chain of the papers for ``point`` on ``preset``: the load
    distribution (000 eq. 7-25, 004 eq. 14-22), friction and efficiency (002 eq. 2-19), wear
    and precision loss (004 eq. 33-35 or 001 eq. 32-38) and fatigue life (000 eq. 29)."""
    geometry = preset.geometry
    if point.jammed_rollers > geometry.n_rollers:
        raise ParameterError("jammed_rollers", f"must be <= n_rollers = {geometry.n_rollers}")
    mesh = meshing(geometry, point.misalignment, carrier_angle_rad=point.carrier_angle_rad)
    loads = solve_load_distribution(
        geometry,
        point.axial_load_n,
        radial_load_n=point.radial_load_n,
        carrier_angle_rad=point.carrier_angle_rad,
        clearance_screw_roller_m=mesh.axial_clearance_screw_roller_m,
        clearance_roller_nut_m=mesh.axial_clearance_roller_nut_m,
        case=point.case,
        elastic_errors=point.elastic_errors,
    )
    torque = friction_torque(
        geometry,
        preset.friction,
        loads.screw_roller_n,
        loads.roller_nut_n,
        point.screw_speed_rad_s,
        jammed=point.jammed_rollers,
    )
    jammed = np.arange(geometry.n_rollers) < point.jammed_rollers
    slip = np.where(
        jammed,
        slip_speed_m_s(geometry, mesh, point.screw_speed_rad_s, jammed=True),
        slip_speed_m_s(geometry, mesh, point.screw_speed_rad_s),
    )[:, None]
    return ModelResult(
        point=point,
        loads=loads,
        meshing=mesh,
        friction=torque,
        efficiency=float(efficiency(geometry, point.axial_load_n, torque.total_nm)),
        precision_loss_rate_m_per_s=float(
            precision_loss_rate_m_per_s(geometry, preset.wear, loads.screw_roller_n, slip)
        ),
        fatigue_life_h=float(
            fatigue_life_h(geometry, preset.fatigue, loads.screw_roller_n, point.screw_speed_rad_s)
        ),
    )
