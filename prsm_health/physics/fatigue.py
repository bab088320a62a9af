"""Rolling-contact fatigue life (paper 000 eq. 29) and Palmgren-Miner damage.

Paper 000 (Dong et al., Processes 2022) eq. 29, the ball-screw stress-life estimate:
L_S = N_s (kappa_s + 1) / (60 w_s kappa_s (kappa_s + 2)) hours for w_s in rpm, with
N_s = k_alpha^m_s N_0 and kappa_s = d_s / d_r. In SI: the screw survives
N_s (kappa_s + 1) / (kappa_s (kappa_s + 2)) revolutions, i.e. a life of that times
2 pi / |omega_s| seconds. Damage accumulates linearly (Palmgren-Miner): dD/dt = 1 / L.

Assumptions (the paper leaves these open):

* The stress ratio is k_alpha = p_ref / p_max with p_max the Hertz maximum pressure of the most
  loaded screw-roller contact (the roller-nut contact is conformal and less stressed) and
  p_ref = FatigueParameters.reference_pressure_pa. With m_s = 6 the life goes as p_max^-6,
  i.e. as Q^-2.
* p_ref = 2.69 GPa calibrates 000's case 1 at F_a = 20 kN, F_r = 4 kN, 300 rpm (peak contact
  force 200.4 N from :func:`prsm_health.physics.load_distribution.solve_load_distribution` on
  the dong2022-downhole preset, p_max = 2.418 GPa) to the published ~7,000 h. The calibration
  leaves out the elastic errors that 000's case 1 includes (with them 200.75 N: 0.3 % in
  life). The other
  published points do not follow: the same model gives about 17,000 h at 10 kN (paper
  ~12,000 h) and about 1,300 h at 55 kN (paper ~4,000 h); no Hertz-stress ratio with
  m_s = 6 reproduces 000's flatter curve.
* Life and damage use |omega_s|: the direction of rotation does not matter. Zero speed or
  zero load gives an infinite life and zero damage rate (never NaN).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from prsm_health.physics.errors import ParameterError
from prsm_health.physics.geometry import Geometry
from prsm_health.physics.hertz import thread_contacts
from prsm_health.physics.parameters import FatigueParameters
from prsm_health.physics.wear import validate_contact_loads

FloatArray = NDArray[np.float64]

_SECONDS_PER_HOUR = 3600.0


def stress_cycles_per_screw_revolution(geometry: Geometry) -> float:
    """kappa_s (kappa_s + 2) / (kappa_s + 1) with kappa_s = d_s / d_r (paper 000 eq. 29)."""
    kappa = geometry.screw_radius_m / geometry.roller_radius_m
    return kappa * (kappa + 2.0) / (kappa + 1.0)


def damage_rate_per_s(
    geometry: Geometry,
    params: FatigueParameters,
    screw_roller_n: ArrayLike,
    screw_speed_rad_s: ArrayLike,
) -> FloatArray:
    """Palmgren-Miner damage rate 1 / L [1/s] (paper 000 eq. 29 inverted).

    dD/dt = (p_max / p_ref)^m_s |omega_s| cycles_per_rev / (2 pi N_0), p_max over the last two
    axes (n_rollers, n_threads) of ``screw_roller_n``; the result broadcasts the remaining
    leading dims with ``screw_speed_rad_s``. Zero at zero load or zero speed.
    """
    forces = validate_contact_loads(geometry, screw_roller_n)
    return damage_rate_from_peak_per_s(
        geometry, params, forces.max(axis=(-2, -1)), screw_speed_rad_s
    )


def damage_rate_from_peak_per_s(
    geometry: Geometry,
    params: FatigueParameters,
    peak_force_n: ArrayLike,
    screw_speed_rad_s: ArrayLike,
) -> FloatArray:
    """:func:`damage_rate_per_s` from the largest screw-roller contact force (000 eq. 29).

    ``peak_force_n`` (>= 0, the most loaded contact of each load case) broadcasts with
    ``screw_speed_rad_s``; for callers that track the peak force only (the truth simulator).
    """
    peak_force = np.asarray(peak_force_n, dtype=np.float64)
    if not (np.isfinite(peak_force).all() and (peak_force >= 0.0).all()):
        raise ParameterError("peak_force_n", "must be finite and >= 0")
    speed = np.asarray(screw_speed_rad_s, dtype=np.float64)
    if not np.isfinite(speed).all():
        raise ParameterError("screw_speed_rad_s", "must be finite")
    peak = thread_contacts(geometry).screw_roller.max_pressure_pa(peak_force)
    try:
        shape = np.broadcast_shapes(peak.shape, speed.shape)
    except ValueError as exc:
        raise ParameterError(
            "screw_speed_rad_s",
            f"shape {speed.shape} does not broadcast with the load cases {peak.shape}",
        ) from exc
    ratio = (peak / params.reference_pressure_pa) ** params.stress_exponent
    rate = (
        ratio
        * np.abs(speed)
        * stress_cycles_per_screw_revolution(geometry)
        / (2.0 * math.pi * params.reference_cycles)
    )
    return np.asarray(np.broadcast_to(rate, shape), dtype=np.float64)


def fatigue_life_h(
    geometry: Geometry,
    params: FatigueParameters,
    screw_roller_n: ArrayLike,
    screw_speed_rad_s: ArrayLike,
) -> FloatArray:
    """Fatigue life L_S in hours (paper 000 eq. 29); inf at zero load or zero speed."""
    rate = damage_rate_per_s(geometry, params, screw_roller_n, screw_speed_rad_s)
    with np.errstate(over="ignore"):  # a denormal damage rate means an infinite life
        life_s = np.divide(1.0, rate, out=np.full_like(rate, np.inf), where=rate > 0.0)
    return np.asarray(life_s / _SECONDS_PER_HOUR, dtype=np.float64)


class DutyBlock(NamedTuple):
    """One block of a duty cycle: constant contact forces and screw speed for a duration."""

    duration_s: float
    screw_roller_n: ArrayLike
    screw_speed_rad_s: float


def miner_damage(
    geometry: Geometry, params: FatigueParameters, blocks: Sequence[DutyBlock]
) -> float:
    """Palmgren-Miner damage D = sum of duration / life over the blocks (1.0 = end of life)."""
    if not blocks:
        return 0.0
    durations = np.array([block.duration_s for block in blocks], dtype=np.float64)
    if not (np.isfinite(durations).all() and (durations >= 0.0).all()):
        raise ParameterError("duration_s", "block durations must be finite and >= 0")
    try:
        forces = np.stack([np.asarray(block.screw_roller_n, dtype=np.float64) for block in blocks])
    except ValueError as exc:
        raise ParameterError("screw_roller_n", f"blocks differ in shape: {exc}") from exc
    speeds = np.array([block.screw_speed_rad_s for block in blocks], dtype=np.float64)
    return float(np.sum(durations * damage_rate_per_s(geometry, params, forces, speeds)))
