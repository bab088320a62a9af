"""Wear of the screw-roller thread flanks and the precision loss it causes (papers 004, 001).

Both papers wear only the screw-roller interface (it slides; the roller-nut interface rolls).
Per contact (roller i, thread j) with normal force Q, Hertz semi-axes a, b and slip speed v:

* ``"archard"``, modified Archard of paper 004 eq. 33-34 (the default of a preset whose
  ``wear`` section says nothing is ``"fractal"``, parameters.WearParameters):
  dh/dt = K Q b sin(lambda) v / (pi a b H L_S0) = K Q sin(lambda) v / (pi a H L_S0).
* ``"fractal"``, paper 001 eq. 32-35 and 38 with the fractal real area A_r of
  :mod:`prsm_health.physics.fractal`: dh/dt = K_w^E K_w A_r v / A_n with the effective wear
  coefficient K_w^E = b sin(lambda_r) / P_r (eq. 33) and A_n = pi a b (eq. 35), i.e.
  dh/dt = K_w A_r sin(lambda_r) v / (pi a P_r).

The precision-loss rate is the sum of dh/dt over all threads of all rollers (004 eq. 35;
001 eq. 37-38 summed over every roller as in its eq. 1).

Assumptions (the papers leave these open):

* 004's L_S0 ("length of the abraded areas of the screw" in its nomenclature, which gives no
  value) and lambda are the roller lead P_r (= pitch, single-start roller) and the roller
  helix angle lambda_r, so 004's factor b sin(lambda) / L_S0 is exactly 001's effective wear
  coefficient K_w^E (eq. 33; same authors). The two models then differ only in the wear
  term: K Q / H (Archard) against K_w A_r (fractal). Reading L_S0 as 004's 100 mm stroke
  would divide the Archard rate by 50.
* Precision loss sums all rollers and threads (one roller would be 1 / n_rollers of it).
* The fractal model uses A_r as defined in :mod:`prsm_health.physics.fractal` (eq. 21's
  truncated-area integral, not halved, not capped at pi a b).
* H is the hardness of the softer of screw and roller.
* The slip speed is the caller's (paper 001 eq. 30 / 004 eq. 32, from
  :mod:`prsm_health.physics.meshing`); it broadcasts against the contact array
  (..., n_rollers, n_threads) with numpy's rules: a scalar, (..., 1, 1) per operating point,
  (..., n_rollers, 1) per roller (a jammed roller slides faster), or per contact. A 1-D
  speed array is refused (it would pair with the thread axis).
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

from prsm_health.physics.errors import ParameterError
from prsm_health.physics.fractal import fractal_surface, real_contact_area_m2
from prsm_health.physics.geometry import Geometry
from prsm_health.physics.hertz import thread_contacts
from prsm_health.physics.parameters import WearParameters

FloatArray = NDArray[np.float64]


def validate_contact_loads(geometry: Geometry, screw_roller_n: ArrayLike) -> FloatArray:
    """Screw-roller contact forces as a float array of shape (..., n_rollers, n_threads),
    finite and >= 0 (refused by the name ``screw_roller_n``)."""
    forces = np.asarray(screw_roller_n, dtype=np.float64)
    shape = (geometry.n_rollers, geometry.n_threads)
    if forces.shape[-2:] != shape:
        raise ParameterError(
            "screw_roller_n", f"must have shape (..., {shape[0]}, {shape[1]}), got {forces.shape}"
        )
    if not (np.isfinite(forces).all() and (forces >= 0.0).all()):
        raise ParameterError("screw_roller_n", "contact forces must be finite and >= 0")
    return forces


@cache
def _sliding_factor_per_m2(geometry: Geometry) -> float:
    """sin(lambda_r) / (pi a_1 P_r) with a_1 the semi-major axis at Q = 1 N [m^-2 N^-1/3].

    a = a_1 Q^(1/3) (004 eq. 26), so sin(lambda_r) / (pi a P_r) = this / Q^(1/3).
    """
    a_unit, _ = thread_contacts(geometry).screw_roller.semi_axes_m(1.0)
    roller_lead_m = geometry.pitch_m  # single-start roller
    return math.sin(geometry.roller_helix_angle_rad) / (math.pi * float(a_unit) * roller_lead_m)


def wear_depth_rate_m_per_s(
    geometry: Geometry,
    params: WearParameters,
    screw_roller_n: ArrayLike,
    slip_speed_m_s: ArrayLike,
) -> FloatArray:
    """Wear depth rate dh/dt of every screw-roller contact [m/s] (004 eq. 34; 001 eq. 34).

    ``params.model`` chooses modified Archard (004) or the fractal real area (001).

    Shape: ``screw_roller_n`` (..., n_rollers, n_threads) broadcast with ``slip_speed_m_s``.
    Exactly zero for unloaded contacts and at zero slip speed.
    """
    forces = validate_contact_loads(geometry, screw_roller_n)
    speed = np.asarray(slip_speed_m_s, dtype=np.float64)
    if not (np.isfinite(speed).all() and (speed >= 0.0).all()):
        raise ParameterError("slip_speed_m_s", "slip speeds must be finite and >= 0")
    if speed.ndim == 1:  # would silently pair with the thread axis
        raise ParameterError(
            "slip_speed_m_s",
            "a 1-D slip speed is ambiguous: pass speeds per operating point as [..., None, None] "
            "or per roller as shape (..., n_rollers, 1)",
        )
    try:
        np.broadcast_shapes(forces.shape, speed.shape)
    except ValueError as exc:
        raise ParameterError(
            "slip_speed_m_s",
            f"shape {speed.shape} does not broadcast with the contact forces {forces.shape}",
        ) from exc
    cbrt_load = np.cbrt(forces)
    factor = _sliding_factor_per_m2(geometry)
    if params.model == "archard":
        # K Q sin(lambda_r) v / (pi a H P_r) with Q / a = Q^(2/3) / a_1.
        hardness = min(geometry.screw.hardness_pa, geometry.roller.hardness_pa)
        wear = params.archard_coefficient / hardness * factor * cbrt_load * cbrt_load
    else:
        # K_w A_r sin(lambda_r) v / (pi a P_r) with a = a_1 Q^(1/3); A_r = 0 where Q = 0.
        surface = fractal_surface(geometry.screw, geometry.roller, params.surface_roughness_ra_m)
        area = real_contact_area_m2(surface, forces)
        per_cbrt = np.divide(area, cbrt_load, out=np.zeros_like(area), where=forces > 0.0)
        wear = params.adhesive_wear_coefficient * factor * per_cbrt
    return np.asarray(wear * speed, dtype=np.float64)


def precision_loss_rate_m_per_s(
    geometry: Geometry,
    params: WearParameters,
    screw_roller_n: ArrayLike,
    slip_speed_m_s: ArrayLike,
) -> FloatArray:
    """Precision-loss rate: dh/dt summed over all threads and rollers [m/s] (004 eq. 35,
    001 eq. 38). Shape: the leading dims of the broadcast of forces and slip speed."""
    rate = wear_depth_rate_m_per_s(geometry, params, screw_roller_n, slip_speed_m_s)
    return np.asarray(rate.sum(axis=(-2, -1)), dtype=np.float64)
