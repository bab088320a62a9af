"""Friction torque of a PRSM, jammed rollers and efficiency (paper 002, Li et al. 2020).

Per thread contact, paper 002 sums four losses (eq. 2-14): elastic hysteresis (eq. 2), spin
sliding (eq. 3), differential (Heathcote) sliding (eq. 4) and lubricant viscous rolling
resistance (eq. 5-11). A jammed roller only orbits with the carrier and slides on the screw and
the nut (eq. 15-16); eq. 17-18 scale this by the number of jammed rollers, here it is done per
roller so that unequal roller loads are handled. Efficiency is eq. 19 with the lead.

Every term is a screw-shaft torque obtained from the power it dissipates, P / omega_s, so the
arms are the same for both interfaces. In the carrier frame (nut fixed, screw at omega_s,
rolling without slip at the pitch circles r_s, r_r, r_n = r_s + 2 r_r), the rolling speed is
v = omega_s r_s r_n / (r_s + r_n) at both interfaces (paper 002 eq. 10 with the mapping below),
so a resisting tangential force F costs the screw F * r_arm with r_arm = r_s r_n / (r_s + r_n).

Because every term is a power law of the normal load Q, the model keeps per interface only the
sums over threads of Q^(4/3), Q^(5/3), Q^0.47 and Q, multiplied by constants computed once per
(geometry, parameters).

Assumptions that paper 002 leaves open:

- Referral to the screw: the dissipated power divided by omega_s. Paper 002 eq. 11 and 16 use
  the arms r_s and r_s + 2 r_r instead; they are not power-consistent. The common arm is
  r_arm = r_s r_n / (r_s + r_n) (8.44 mm for li2020-jamming against 13.5 / 22.5 mm in eq. 16).
- Kinematics: nut fixed, rolling without slip at the nominal pitch radii, helix angles
  neglected in the kinematics; the nut contact radius is r_s + 2 r_r.
- Eq. 10 mapping: the roller thread is the "ball" of diameter d_W = 2R, R = r_r / sin(beta)
  (paper 004 eq. 25); the bearing contact angle (from the radial plane) is pi/2 - beta, so
  d_W cos(alpha) = 2 r_r; d_m = 2 (r_s + r_r). Then v = omega_s r_s r_n / (r_s + r_n).
- Raceway curvature coefficient f: the screw and nut flanks are straight in profile (the Hertz
  model of :mod:`prsm_health.physics.hertz`), so f -> infinity: (2f + 1)^2 / (16 f^2) -> 1/4 in
  eq. 4 and f R / (2f - 1) -> R / 2 in eq. 6. 002 does not define R; eq. 6 is Harris's
  R_y = f D / (2f - 1) with D the ball diameter, so R is read as d_W there and the limit is
  R_Y = d_W / 2 = R, the ball radius: k = R_Y / R_X, R_X the relative radius of curvature in
  the rolling (circumferential) direction. (With R read as the radius, k and the viscous
  torque would be 2^-0.348 = 0.79 times these.) In eq. 4, R is read as the ball radius (a / R,
  semi-axis over radius); read as d_W the differential term would be a quarter of this. The
  term is 4e-4 to 1.5e-3 of the torque on the presets, so the reading moves the total by
  0.11 % at most. 002 Table 1 lists f_m = 0.75 (and f_k = 43 N^(2/3)/mm), not
  defined in its text; if f_m were this f (a curved flank the Hertz model does not have),
  eq. 4's factor would be 0.69 instead of 1/4 and eq. 6's k three times ours (the viscous
  torque 1.47 times).
- Eq. 2 (hysteresis): B m_b a is read as b_roll / 2, half the contact semi-axis along the
  rolling direction, i.e. Johnson's rolling resistance of an elliptic contact, moment
  (3/16) gamma Q b_roll; its dissipated power is that moment times v / R_X.
- Eq. 3 (spin): the Hertz pressure has the square root, p = 3Q/(2 pi a b) sqrt(1 - x^2/a^2 -
  y^2/b^2) (as printed the integral would not return Q). Closed form: iint p r dA =
  Q a (3/8) E(1 - 1/kappa^2). Its power is the moment times the spin speed
  omega_spin = v sin(beta) (1/r_r +- 1/r_c) (+ screw, - nut); this replaces the "cos alpha".
  (geometry's R = r_r / sin(beta) and contact radius r_s + r_r - R cos(beta), 004 eqs. 24-25,
  take the flank angle from the other plane: the two readings agree only at beta = 45 deg,
  the flank angle of every bundled preset.)
  The whole contact is taken to slip with Coulomb f_s (an upper bound for a lubricated
  contact); with a 45 deg flank the spin speed equals the rolling speed, and this term is
  about 90 % of a healthy roller's torque for li2020-jamming.
- Eq. 4 (differential sliding): the slip is across the contact, so the semi-axis transverse to
  rolling is used (the major axis at the screw, the minor axis at the nut, whose ellipse is
  elongated circumferentially); R is the effective ball radius; the force resists rolling.
- Eq. 5 (viscous): the printed "(Sum rho)_s^2" is R_X^2 (Houpert's rolling force
  F = 2.86 E' R_X^2 k^0.348 G^0.022 U^0.66 W^0.47); E' = 2 / ((1-nu1^2)/E1 + (1-nu2^2)/E2);
  U uses the rolling speed v of eq. 10; the force is per thread contact and vanishes for an
  unloaded contact (W = 0).
- Jammed roller (eq. 15-16): it does not spin relative to the carrier, which keeps the speed set
  by the healthy rollers, so it slides with speed v at both interfaces; each interface uses its
  own loads, F_h = f_s sum_j Q_j; its rolling losses (eq. 2-11) are replaced by this sliding.
  Eq. 17 as printed reads "(N - x) M_s / N = M_hs x"; the "=" is taken as "+". Eq. 12-13's
  "N sum_i" become per-roller sums.
- Standstill: the viscous term vanishes at zero speed and the others are load-dependent, so the
  torque at omega_s = 0 is the breakaway (static) estimate. Torques are magnitudes for |omega_s|.
- Efficiency (eq. 19) is the forward (screw driving) efficiency with the lead L = n_s p; it is
  defined as 0 at zero axial load.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import ellipe

from prsm_health.physics.errors import DomainError, ParameterError
from prsm_health.physics.geometry import Geometry
from prsm_health.physics.hertz import ContactPair, thread_contacts
from prsm_health.physics.parameters import FrictionParameters

FloatArray = NDArray[np.float64]

# Houpert's EHL rolling force (paper 002 eq. 5): prefactor and exponents of k, G, U, W.
_HOUPERT_FACTOR = 2.86
_K_EXP, _G_EXP, _U_EXP, _W_EXP = 0.348, 0.022, 0.66, 0.47
#: The viscous torque goes as |omega_s|^0.66 and (per contact) Q^0.47 (Houpert's U and W
#: exponents); the other losses do not depend on speed.
VISCOUS_SPEED_EXPONENT = _U_EXP
VISCOUS_LOAD_EXPONENT = _W_EXP
# Differential sliding factor of paper 002 eq. 4: 0.08 (2f + 1)^2 / (16 f^2) for f -> infinity.
_DIFFERENTIAL_FACTOR = 0.08 / 4.0


def spin_integral(kappa: float) -> float:
    """I(kappa) with iint p(x, y) sqrt(x^2 + y^2) dA = Q a I over the Hertz ellipse.

    Paper 002 eq. 3 (with the Hertz pressure): a is the semi-major axis, kappa = a/b >= 1.
    Closed form (3/8) E(1 - 1/kappa^2), E the complete elliptic integral of the second kind
    (polar coordinates scaled to the ellipse split the integral into int r^2 sqrt(1 - r^2) dr
    = pi/16 and 4 E); 3 pi / 16 for a circle. The tests check it against 2-D quadrature.
    """
    if not (math.isfinite(kappa) and kappa >= 1.0):
        raise ParameterError("kappa", f"must be finite and >= 1, got {kappa!r}")
    return 3.0 / 8.0 * float(ellipe(1.0 - 1.0 / kappa**2))


def rolling_speed_m_s(geometry: Geometry, screw_speed_rad_s: ArrayLike) -> FloatArray:
    """Rolling speed v of the roller thread over the screw and nut, paper 002 eq. 10.

    v = (pi n / 30) [1 - (d_W cos(alpha) / d_m)^2] d_m / 4 with pi n / 30 = |omega_s|, the
    effective ball d_W = 2 r_r / sin(beta) (paper 004 eq. 25), alpha = pi/2 - beta and
    d_m = 2 (r_s + r_r); this equals |omega_s| r_s r_n / (r_s + r_n).
    """
    ball_diameter = 2.0 * geometry.effective_ball_radius_m
    cos_contact = math.sin(geometry.flank_angle_rad)
    pitch_diameter = 2.0 * geometry.carrier_radius_m
    ratio = ball_diameter * cos_contact / pitch_diameter
    speed: FloatArray = np.abs(np.asarray(screw_speed_rad_s, dtype=float))
    return speed * ((1.0 - ratio**2) * pitch_diameter / 4.0)


@dataclass(frozen=True)
class _Coefficients:
    """Load-independent factors of both interfaces (index 0 screw-roller, 1 roller-nut).

    Each component torque of one roller is coefficient @ (sum over its threads of Q^e):
    hysteresis and spin with e = 4/3, differential with e = 5/3, viscous with e = 0.47 (times
    |omega_s|^0.66), jammed sliding with e = 1.
    """

    hysteresis: FloatArray
    spin: FloatArray
    differential: FloatArray
    viscous: FloatArray
    sliding: FloatArray


def _interface_terms(
    geometry: Geometry,
    params: FrictionParameters,
    pair: ContactPair,
    contact_radius_m: float,
    spin_sign: float,
) -> tuple[float, float, float, float, float]:
    """Screw-referred coefficients of one interface (paper 002 eq. 2-11, 16)."""
    arm = float(rolling_speed_m_s(geometry, 1.0))
    ball_radius = geometry.effective_ball_radius_m
    profile_curvature = 1.0 / ball_radius  # roller arc against a straight flank
    rolling_curvature = pair.curvature_sum_per_m - profile_curvature
    if not rolling_curvature > 0.0:
        raise ParameterError(
            "geometry", f"rolling-direction curvature sum {rolling_curvature!r} 1/m is not > 0"
        )
    a_unit, b_unit = (float(x) for x in pair.semi_axes_m(1.0))
    rolls_along_minor = rolling_curvature >= profile_curvature
    rolling_axis = b_unit if rolls_along_minor else a_unit
    transverse_axis = a_unit if rolls_along_minor else b_unit
    f_s = params.sliding_friction_coefficient

    hysteresis = 3.0 / 16.0 * params.hysteresis_loss_coefficient * rolling_axis
    hysteresis *= rolling_curvature * arm
    spin_speed_ratio = (
        arm
        * math.sin(geometry.flank_angle_rad)
        * (1.0 / geometry.roller_radius_m + spin_sign / contact_radius_m)
    )
    spin = spin_integral(pair.kappa) * f_s * a_unit * spin_speed_ratio
    differential = _DIFFERENTIAL_FACTOR * f_s * (transverse_axis / ball_radius) ** 2 * arm

    modulus = 2.0 / pair.compliance_per_pa
    radius_x = 1.0 / rolling_curvature
    k = ball_radius / radius_x
    g = modulus * params.pressure_viscosity_coefficient_per_pa
    u_per_rad_s = params.lubricant_viscosity_pa_s * arm / (modulus * radius_x)
    w_per_n = 1.0 / (modulus * radius_x**2)
    viscous = (
        _HOUPERT_FACTOR
        * modulus
        * radius_x**2
        * k**_K_EXP
        * g**_G_EXP
        * u_per_rad_s**_U_EXP
        * w_per_n**_W_EXP
        * arm
    )
    return hysteresis, spin, differential, viscous, f_s * arm


@cache
def _coefficients(geometry: Geometry, params: FrictionParameters) -> _Coefficients:
    """Both interfaces' coefficients of 002 eq. 2-10, computed once per (geometry,
    parameters); the nut's at the contact radius r_s + 2 r_r (002 eq. 4, 16)."""
    contacts = thread_contacts(geometry)
    nut_contact_radius = geometry.carrier_radius_m + geometry.roller_radius_m
    screw = _interface_terms(geometry, params, contacts.screw_roller, geometry.screw_radius_m, 1.0)
    nut = _interface_terms(geometry, params, contacts.roller_nut, nut_contact_radius, -1.0)
    table = np.array(list(zip(screw, nut, strict=True)), dtype=float)
    table.setflags(write=False)
    return _Coefficients(*table)


@dataclass(frozen=True)
class FrictionTorque:
    """Friction torque referred to the screw shaft, per loss and per roller [N m], >= 0.

    Each array has shape (..., n_rollers); the leading dims are those of the loads broadcast
    with the screw speed. Healthy rollers have zero jammed_sliding_nm; jammed ones have zero
    rolling losses (paper 002 eq. 17).
    """

    hysteresis_nm: FloatArray
    spin_nm: FloatArray
    differential_nm: FloatArray
    viscous_nm: FloatArray
    jammed_sliding_nm: FloatArray

    @property
    def per_roller_nm(self) -> FloatArray:
        """Total torque each roller costs the screw, shape (..., n_rollers) (002 eq. 12-13)."""
        return (
            self.hysteresis_nm
            + self.spin_nm
            + self.differential_nm
            + self.viscous_nm
            + self.jammed_sliding_nm
        )

    @property
    def total_nm(self) -> FloatArray:
        """Total screw friction torque M = M_s + M_n, shape (...) (paper 002 eq. 14, 18)."""
        total: FloatArray = self.per_roller_nm.sum(axis=-1)
        return total


def _validated_loads(
    geometry: Geometry, screw_roller_n: ArrayLike, roller_nut_n: ArrayLike
) -> FloatArray:
    """Both load arrays stacked by interface: shape (..., 2, n_rollers, n_threads)."""
    expected = (geometry.n_rollers, geometry.n_threads)
    arrays = []
    for name, value in (("screw_roller_n", screw_roller_n), ("roller_nut_n", roller_nut_n)):
        try:
            array = np.asarray(value, dtype=float)
        except (TypeError, ValueError) as exc:
            raise ParameterError(name, f"must be a numeric array: {exc}") from exc
        if array.ndim < 2 or array.shape[-2:] != expected:
            raise ParameterError(
                name, f"shape {array.shape} must end with (n_rollers, n_threads) = {expected}"
            )
        arrays.append(array)
    if arrays[0].shape != arrays[1].shape:
        raise ParameterError(
            "roller_nut_n",
            f"shape {arrays[1].shape} differs from screw_roller_n {arrays[0].shape}",
        )
    loads = np.stack(arrays, axis=-3)
    # min >= 0 is False for NaN and negatives; a finite sum excludes +inf.
    if not (loads.min() >= 0.0 and math.isfinite(loads.sum())):
        for name, array in zip(("screw_roller_n", "roller_nut_n"), arrays, strict=True):
            if not bool(np.all((array >= 0.0) & np.isfinite(array))):
                raise ParameterError(name, "normal loads must be finite and >= 0")
    return loads


def _jammed_mask(geometry: Geometry, jammed: ArrayLike | int | None) -> NDArray[np.bool_] | None:
    """Boolean mask (..., n_rollers) of jammed rollers, or None when no roller is jammed."""
    n_rollers = geometry.n_rollers
    if jammed is None:
        return None
    if isinstance(jammed, int | np.integer) and not isinstance(jammed, bool | np.bool_):
        if not 0 <= jammed <= n_rollers:
            raise ParameterError("jammed", f"count must be in [0, {n_rollers}], got {jammed}")
        return np.arange(n_rollers) < jammed
    mask = np.asarray(jammed)
    if mask.dtype != np.bool_ or mask.ndim < 1 or mask.shape[-1] != n_rollers:
        raise ParameterError(
            "jammed",
            f"must be an int count or a bool array ending with n_rollers = {n_rollers}, "
            f"got dtype {mask.dtype} shape {mask.shape}",
        )
    return mask


def friction_torque(
    geometry: Geometry,
    params: FrictionParameters,
    screw_roller_n: ArrayLike,
    roller_nut_n: ArrayLike,
    screw_speed_rad_s: ArrayLike,
    *,
    jammed: ArrayLike | int | None = None,
) -> FrictionTorque:
    """Screw friction torque of a PRSM from its thread contact loads, paper 002 eq. 2-18.

    screw_roller_n, roller_nut_n: normal contact forces Q of shape (..., n_rollers, n_threads).
    screw_speed_rad_s: screw speed, broadcast against the leading dims; its sign is ignored
    (magnitudes are returned; callers apply the sign opposing motion).
    jammed: None, a count x (the first x rollers are jammed) or a bool mask (..., n_rollers).
    Returns the screw-referred torque per loss and per roller (see the module docstring).
    """
    loads = _validated_loads(geometry, screw_roller_n, roller_nut_n)
    speed = np.asarray(screw_speed_rad_s, dtype=float)
    if not np.isfinite(speed).all():
        raise ParameterError("screw_speed_rad_s", "must be finite")
    mask = _jammed_mask(geometry, jammed)
    mask_leading = () if mask is None else mask.shape[:-1]
    try:
        leading = np.broadcast_shapes(loads.shape[:-3], speed.shape, mask_leading)
    except ValueError as exc:
        raise ParameterError(
            "screw_speed_rad_s",
            f"shape {speed.shape} (jammed: {mask_leading}) does not broadcast with the "
            f"loads' leading shape {loads.shape[:-3]}",
        ) from exc
    shape = (*leading, geometry.n_rollers)
    coefficients = _coefficients(geometry, params)

    # Q^(1/3) and Q^0.47 as exp(e ln Q): one log serves both and is faster than cbrt + power
    # (an unloaded contact gives ln 0 = -inf, exp(-inf) = 0). Work buffers are reused (out=),
    # as fresh large temporaries cost more than the arithmetic. Sums over threads use a product
    # with ones (faster than .sum for short rows): shape (..., 2, n_rollers); then
    # coefficient @ sums adds the two interfaces.
    ones = np.ones(geometry.n_threads)
    with np.errstate(divide="ignore"):
        log_load = np.log(loads)
    cube_root = np.multiply(log_load, 1.0 / 3.0)
    np.exp(cube_root, out=cube_root)
    power = np.multiply(loads, cube_root)
    sum_q43 = power @ ones
    sum_q53 = np.multiply(power, cube_root, out=cube_root) @ ones
    sum_q047 = np.exp(np.multiply(log_load, _W_EXP, out=log_load), out=log_load) @ ones
    speed_factor = np.abs(speed)[..., np.newaxis] ** _U_EXP
    components = [
        coefficients.hysteresis @ sum_q43,
        coefficients.spin @ sum_q43,
        coefficients.differential @ sum_q53,
        (coefficients.viscous @ sum_q047) * speed_factor,
    ]
    if mask is None:
        sliding: FloatArray = np.zeros(shape)
    else:
        sliding = np.where(mask, coefficients.sliding @ (loads @ ones), 0.0)
        components = [np.where(mask, 0.0, value) for value in components]
    hysteresis, spin, differential, viscous, sliding = (
        value if value.shape == shape else np.broadcast_to(value, shape)
        for value in (*components, sliding)
    )
    return FrictionTorque(
        hysteresis_nm=hysteresis,
        spin_nm=spin,
        differential_nm=differential,
        viscous_nm=viscous,
        jammed_sliding_nm=sliding,
    )


def jammed_to_rolling_ratio(
    geometry: Geometry,
    params: FrictionParameters,
    screw_roller_n: ArrayLike,
    roller_nut_n: ArrayLike,
    screw_speed_rad_s: ArrayLike,
) -> FloatArray:
    """r = (torque of a roller when jammed) / (its rolling torque), shape (..., n_rollers).

    Paper 002 eq. 16 over eq. 12-13 for one roller; with equal roller loads,
    M(x) / M(0) = 1 + x (r - 1) / N (eq. 17-18). Raises DomainError for an unloaded roller.
    """
    rolling = friction_torque(
        geometry, params, screw_roller_n, roller_nut_n, screw_speed_rad_s
    ).per_roller_nm
    jammed = friction_torque(
        geometry,
        params,
        screw_roller_n,
        roller_nut_n,
        screw_speed_rad_s,
        jammed=geometry.n_rollers,
    ).jammed_sliding_nm
    if not bool(np.all(rolling > 0.0)):
        raise DomainError("jammed_to_rolling_ratio: a roller carries no load (ratio 0/0)")
    ratio: FloatArray = jammed / rolling
    return ratio


def efficiency(
    geometry: Geometry, axial_load_n: ArrayLike, friction_torque_nm: ArrayLike
) -> FloatArray:
    """Forward efficiency eta = F L / 2pi / (F L / 2pi + M), paper 002 eq. 19 with the lead.

    axial_load_n (F >= 0) and friction_torque_nm (M >= 0) broadcast together; eta = 0 where
    F L / 2pi + M = 0 (no output power at zero load).
    """
    load = np.asarray(axial_load_n, dtype=float)
    torque = np.asarray(friction_torque_nm, dtype=float)
    for name, value in (("axial_load_n", load), ("friction_torque_nm", torque)):
        if not bool(np.all((value >= 0.0) & np.isfinite(value))):
            raise ParameterError(name, "must be finite and >= 0")
    output_nm = load * (geometry.lead_m / (2.0 * math.pi))
    input_nm = output_nm + torque
    safe_input = np.where(input_nm > 0.0, input_nm, 1.0)
    eta: FloatArray = np.where(input_nm > 0.0, output_nm / safe_input, 0.0)
    return eta
