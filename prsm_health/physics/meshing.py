"""Unloaded meshing of the threads: axial clearances with screw misalignment, contact points, slip.

Paper 004 sections 2.1-2.3 (contact positions and axial clearances of the misaligned PRSM) and
2.6 / paper 001 eq. 30 (slip velocity at the screw-roller contact).

Method. In the frame of one roller (screw axis on z, roller axis at (r_s + r_r, 0)) every loaded
flank is a height function z(x, y):

* screw flank, 004 eq. 5: straight profile at the flank angle, helicoid of lead n_s p,
  z_s = c_s - (rho_s - r_s) tan(beta) + phi_s n_s p / (2 pi), the screw tooth centred on z = 0
  on the line of centres;
* roller flank, 004 eq. 6: arc profile of radius R = r_r / sin(beta) centred on the roller axis,
  single-start helicoid of lead p, the roller tooth centred half a pitch from the screw tooth,
  z_r = p/2 - psi p / (2 pi) - (c_r - R cos(beta) + sqrt(R^2 - rho_r^2)), psi being the angle
  about the roller axis measured from the line of centres;
* nut flank, 004 eq. 10-11: straight profile, helicoid of lead n_n p, facing the other flank of
  the roller tooth on the far side of the roller.

The axial clearance of a flank pair is the minimum over the plane of the axial gap between the
two surfaces (how far one body must slide axially before the flanks touch); its minimiser is the
contact point, which gives the meshing radii r_sr, r_rs and angles theta_sr, theta_rs of
001 eq. 30. The minimum is found on a grid and refined with SLSQP, once per geometry.

Screw misalignment (004 eq. 2-4) is a small rigid motion u(P) = theta x (P - O) + epsilon of
the screw. To first order it moves the screw flank height at a fixed (x, y) by
u_z - grad(z_s) . u_xy, and (the gap being stationary at the contact point) the clearance of
roller i, thread j changes by minus that amount evaluated at the aligned contact point.

Assumptions the papers leave open:

* Screw, roller and nut threads are all right-handed (same hand). 004's aligned clearance of
  0.023 mm is reproduced only so; opposite screw/roller hands give about 0.095 mm.
* The flank angle beta enters as in 004 eq. 5-6: flank slope tan(beta) in the axial section
  and R = r_r / sin(beta) (both conventions coincide for beta = 45 deg, the papers' value).
* The misalignment pivot O is the origin of 004's screw frame: on the nominal screw axis, in
  the plane of the screw tooth of thread 1 (z = p (j - 1) in 004 eq. 5). Thread j of roller i
  meets the screw at z = (j - 1) p + z_c above it, z_c being the aligned contact height; the
  sub-pitch axial phase of each roller's teeth (tau_i n_s p / (2 pi) mod p) is neglected (its
  effect is less than one thread step of the clearance).
* Roller i sits at tau_i = carrier angle + 2 pi (i - 1) / N (004 eq. 4); the tilt angles are
  about the fixed x and y axes (004 eq. 3, rotation R_y R_x); 004's axial offset component is
  not modelled (a common axial shift of the screw is solved by the load distribution).
* The nut tooth reaches over the whole radial band of the roller tooth (004 Table 2 gives no
  nut radii that the geometry keeps); the roller-nut clearance does not depend on it because
  its minimum lies on the line of centres, where equal nut and roller helix angles cancel.
* Slip speed (001 eq. 30 = 004 eq. 32): the roller spins relative to the carrier at
  (r_s + 2 r_r) / r_r times the carrier speed, which is 001 eq. 30's n_s for a standard PRSM and
  makes both pitch points roll without slip together with 004 eq. 30. The axial term "L_s" is
  the screw lead n_s p: the rollers do not move axially relative to the nut, so the roller
  slides along the screw by one lead per screw revolution (the stroke of 004 Table 2 would
  be a travel, not a velocity, and gives a seven times larger speed).
* Jammed roller (paper 002 section 2.3): the roller is seized on its carrier (spin relative to
  the carrier zero) but still revolves at the carrier speed of 004 eq. 30 (set by the healthy
  rollers) and still moves axially with the nut, so its slip is the full relative surface
  speed sqrt(r_sr^2 (w_s - w_p)^2 + (w_s n_s p / (2 pi))^2).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache, lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import minimize

from prsm_health.physics.errors import ConvergenceError, DomainError, ParameterError
from prsm_health.physics.geometry import Geometry, Misalignment

FloatArray = NDArray[np.float64]
GapFunction = Callable[[FloatArray, FloatArray], FloatArray]

#: Grid points per axis of the coarse search for the contact point.
_GRID_POINTS = 241


def screw_flank_height_m(geometry: Geometry, x_m: ArrayLike, y_m: ArrayLike) -> FloatArray:
    """Axial height of the screw's loaded flank at (x, y), roller frame (004 eq. 5).

    Straight profile at the flank angle, helicoid of lead n_s p, tooth half thickness c_s at
    the nominal radius, tooth centred on z = 0 on the line of centres (the +x axis).
    """
    x, y = np.asarray(x_m, dtype=float), np.asarray(y_m, dtype=float)
    rho = np.hypot(x, y)
    return np.asarray(
        geometry.thread_half_thickness_screw_m
        - (rho - geometry.screw_radius_m) * math.tan(geometry.flank_angle_rad)
        + np.arctan2(y, x) * geometry.lead_m / (2.0 * math.pi),
        dtype=float,
    )


def _roller_profile_m(geometry: Geometry, rho_m: FloatArray) -> FloatArray:
    """Axial half thickness of the roller tooth at radius rho: arc of radius R (004 eq. 6)."""
    ball = geometry.effective_ball_radius_m
    chord = np.sqrt(np.maximum(ball**2 - rho_m**2, 0.0))
    return np.asarray(
        geometry.thread_half_thickness_roller_m - ball * math.cos(geometry.flank_angle_rad) + chord,
        dtype=float,
    )


def roller_flank_height_m(geometry: Geometry, x_m: ArrayLike, y_m: ArrayLike) -> FloatArray:
    """Axial height of the roller flank facing the screw at (x, y), roller frame (004 eq. 6).

    Single-start right-hand helicoid of lead p with an arc profile of radius r_r / sin(beta)
    centred on the roller axis; the roller tooth is centred half a pitch above the screw tooth
    on the line of centres.
    """
    x, y = np.asarray(x_m, dtype=float), np.asarray(y_m, dtype=float)
    dx = x - geometry.carrier_radius_m
    psi = np.arctan2(y, -dx)  # about the roller axis, from the line of centres
    return np.asarray(
        geometry.pitch_m / 2.0
        - psi * geometry.pitch_m / (2.0 * math.pi)
        - _roller_profile_m(geometry, np.hypot(dx, y)),
        dtype=float,
    )


def _roller_nut_gap_m(geometry: Geometry, x: FloatArray, y: FloatArray) -> FloatArray:
    """Axial gap between the nut flank and the roller's other flank, far side (004 eq. 10-11)."""
    dx = x - geometry.carrier_radius_m
    roller_top = np.arctan2(y, dx) * geometry.pitch_m / (2.0 * math.pi) + _roller_profile_m(
        geometry, np.hypot(dx, y)
    )
    nut_lead_m = geometry.nut_starts * geometry.pitch_m
    nut_bottom = (
        geometry.pitch_m / 2.0
        - geometry.thread_half_thickness_nut_m
        - (np.hypot(x, y) - geometry.nut_radius_m) * math.tan(geometry.flank_angle_rad)
        + np.arctan2(y, x) * nut_lead_m / (2.0 * math.pi)
    )
    return np.asarray(nut_bottom - roller_top, dtype=float)


def _screw_roller_gap_m(geometry: Geometry, x: FloatArray, y: FloatArray) -> FloatArray:
    """Axial gap between the roller flank and the screw flank, aligned (004 eq. 1)."""
    return roller_flank_height_m(geometry, x, y) - screw_flank_height_m(geometry, x, y)


def _minimum_gap(
    gap: GapFunction,
    bands: tuple[tuple[float, float, float], ...],
    x_range_m: tuple[float, float],
    half_width_m: float,
    name: str,
) -> tuple[float, float, float]:
    """Minimum of ``gap`` over the points whose distance from each band's centre lies in it.

    ``bands`` holds (centre_x_m, inner_radius_m, outer_radius_m) for the bodies' thread flanks
    (root to crest). Coarse grid, then SLSQP on coordinates scaled by ``half_width_m``.
    """
    xs = np.linspace(*x_range_m, _GRID_POINTS)
    ys = np.linspace(-half_width_m, half_width_m, _GRID_POINTS)
    grid_x, grid_y = np.meshgrid(xs, ys)
    inside = np.ones_like(grid_x, dtype=bool)
    for centre, inner, outer in bands:
        rho = np.hypot(grid_x - centre, grid_y)
        inside &= (rho >= inner) & (rho <= outer)
    values = np.where(inside, gap(grid_x, grid_y), np.inf)
    if not np.isfinite(values).any():
        raise ParameterError(name, "the thread flanks do not overlap radially")
    k = np.unravel_index(int(np.argmin(values)), values.shape)
    scale = half_width_m

    def objective(v: FloatArray) -> float:
        return float(gap(np.asarray(v[0] * scale), np.asarray(v[1] * scale)) / scale)

    centres, inners, outers = (np.array(column) / scale for column in zip(*bands, strict=True))

    def margins(v: FloatArray) -> FloatArray:
        rho = np.hypot(v[0] - centres, v[1])
        return np.concatenate((rho - inners, outers - rho))

    start = np.array([grid_x[k], grid_y[k]]) / scale
    result = minimize(
        objective,
        start,
        method="SLSQP",
        constraints=({"type": "ineq", "fun": margins},),
        options={"ftol": 1e-15, "maxiter": 200},
    )
    refined = bool(
        np.all(np.isfinite(result.x))
        and np.all(margins(result.x) >= -1e-9)
        and result.fun <= objective(start)
    )
    if not refined and not result.success:
        raise ConvergenceError(f"{name}: contact point search failed ({result.message})")
    best = (result.x if refined else start) * scale
    return float(best[0]), float(best[1]), float(gap(np.asarray(best[0]), np.asarray(best[1])))


@dataclass(frozen=True)
class _AlignedContact:
    """Load-independent aligned contact of one geometry (roller frame, SI).

    (x_m, y_m): contact point; height_m: screw flank height there; screw_slope: gradient
    (dz_s/dx, dz_s/dy) of the screw flank at the contact point.
    """

    x_m: float
    y_m: float
    height_m: float
    screw_roller_clearance_m: float
    roller_nut_clearance_m: float
    screw_slope: tuple[float, float]


@cache
def _aligned_contact(geometry: Geometry) -> _AlignedContact:
    """Aligned contact points and clearances (004 eq. 1 and 9 without misalignment)."""
    centre = geometry.carrier_radius_m
    crest_r = geometry.roller_crest_radius_m
    x, y, clearance = _minimum_gap(
        lambda gx, gy: _screw_roller_gap_m(geometry, gx, gy),
        (
            (0.0, geometry.screw_root_radius_m, geometry.screw_crest_radius_m),
            (centre, geometry.roller_root_radius_m, crest_r),
        ),
        (centre - crest_r, geometry.screw_crest_radius_m),
        crest_r,
        "geometry.thread_half_thickness_screw_m",
    )
    _, _, nut_clearance = _minimum_gap(
        lambda gx, gy: _roller_nut_gap_m(geometry, gx, gy),
        ((centre, geometry.roller_root_radius_m, crest_r),),
        (centre, centre + crest_r),
        crest_r,
        "geometry.thread_half_thickness_nut_m",
    )
    for field, value in (
        ("geometry.thread_half_thickness_screw_m", clearance),
        ("geometry.thread_half_thickness_nut_m", nut_clearance),
    ):
        if value < 0.0:
            raise ParameterError(
                field, f"the aligned thread flanks overlap by {-value * 1e6:.3f} um"
            )
    rho = math.hypot(x, y)
    tan_beta = math.tan(geometry.flank_angle_rad)
    lead_per_rad = geometry.lead_m / (2.0 * math.pi)
    slope = (
        -tan_beta * x / rho - lead_per_rad * y / rho**2,
        -tan_beta * y / rho + lead_per_rad * x / rho**2,
    )
    return _AlignedContact(
        x_m=x,
        y_m=y,
        height_m=float(screw_flank_height_m(geometry, x, y)),
        screw_roller_clearance_m=clearance,
        roller_nut_clearance_m=nut_clearance,
        screw_slope=slope,
    )


@dataclass(frozen=True, eq=False)
class Meshing:
    """Unloaded meshing state of a PRSM (SI; arrays are read-only, shape (n_rollers, n_threads)).

    axial_clearance_screw_roller_m: g^a_sr(i, j) of 004 eq. 1 / Fig. 8, with misalignment.
    axial_clearance_roller_nut_m: g^a_nr(i, j) of 004 eq. 9 (nut and roller aligned: uniform).
    contact_angle_screw_rad, contact_angle_roller_rad: meshing angles theta_sr, theta_rs of
    001 Fig. 6 / eq. 30, the angular position of the aligned contact point off the line of
    centres about the screw and about the roller axis.
    contact_radius_screw_m, contact_radius_roller_m: meshing radii r_sr, r_rs (001 eq. 30).
    """

    axial_clearance_screw_roller_m: FloatArray
    axial_clearance_roller_nut_m: FloatArray
    contact_angle_screw_rad: float
    contact_angle_roller_rad: float
    contact_radius_screw_m: float
    contact_radius_roller_m: float


def _read_only(array: FloatArray) -> FloatArray:
    array.setflags(write=False)
    return array


def _clearance_loss_phasor_m(
    geometry: Geometry, misalignment: Misalignment
) -> tuple[FloatArray, FloatArray]:
    """The screw-roller clearance a misalignment takes from thread j of a roller at angle tau,
    a_j cos(tau) + b_j sin(tau): returns (a_j, b_j) [m], one per thread (004 eq. 2-4, first
    order). The screw's flank height moves by u_z - grad(z_s) . u_xy at the contact point,
    and every term of it turns with the roller's angle tau while the threads' heights above
    the pivot set the tilt's lever.
    """
    contact = _aligned_contact(geometry)
    x, y = contact.x_m, contact.y_m
    slope_x, slope_y = contact.screw_slope
    tilt_x, tilt_y = misalignment.tilt_x_rad, misalignment.tilt_y_rad
    height = contact.height_m + geometry.pitch_m * np.arange(geometry.n_threads)
    move_x = tilt_y * height + misalignment.offset_x_m
    move_y = -tilt_x * height + misalignment.offset_y_m
    along_cos = tilt_x * y - tilt_y * x - slope_x * move_x - slope_y * move_y
    along_sin = tilt_x * x + tilt_y * y - slope_x * move_y + slope_y * move_x
    return along_cos, along_sin


def smallest_misaligned_clearance(
    geometry: Geometry, misalignment: Misalignment
) -> tuple[float, int, float]:
    """The smallest screw-roller clearance [m] a misalignment leaves at any carrier angle,
    with its thread (0-based) and the roller angle tau [rad] where it is reached.

    Exact, not sampled: thread j's clearance is c - (a_j cos tau + b_j sin tau)
    (:func:`_clearance_loss_phasor_m`), whose minimum over tau is c - hypot(a_j, b_j) at
    tau = atan2(b_j, a_j). Every roller passes every angle as the carrier turns.
    """
    along_cos, along_sin = _clearance_loss_phasor_m(geometry, misalignment)
    loss = np.hypot(along_cos, along_sin)
    thread = int(np.argmax(loss))
    clearance = _aligned_contact(geometry).screw_roller_clearance_m - float(loss[thread])
    angle = math.atan2(float(along_sin[thread]), float(along_cos[thread])) % (2.0 * math.pi)
    return clearance, thread, angle


@lru_cache(maxsize=1024)
def meshing(
    geometry: Geometry, misalignment: Misalignment, *, carrier_angle_rad: float = 0.0
) -> Meshing:
    """Axial clearances and contact points of every thread of every roller (004 eq. 1-12).

    The aligned contact is found once per geometry by minimising the axial flank gap; the
    screw misalignment (004 eq. 2-4: tilt about x and y through the thread-1 pivot, radial
    offset) then changes the clearance of roller i, thread j by the first-order change of the
    screw flank height at that thread's contact point (:func:`_clearance_loss_phasor_m`).
    ``carrier_angle_rad`` turns the roller set (tau_i = carrier angle + 2 pi (i - 1) / N),
    which makes the misaligned clearances periodic in time (and with them the contact forces
    of 004 Fig. 12).

    Raises DomainError (naming roller and thread, 1-based) when the misalignment closes a
    screw-roller clearance below zero, i.e. the flanks would overlap.
    """
    if not math.isfinite(carrier_angle_rad):
        raise ParameterError("carrier_angle_rad", f"not finite: {carrier_angle_rad!r}")
    contact = _aligned_contact(geometry)
    shape = (geometry.n_rollers, geometry.n_threads)
    clearance = np.full(shape, contact.screw_roller_clearance_m)
    if not misalignment.is_aligned:
        tau = carrier_angle_rad + 2.0 * math.pi * np.arange(geometry.n_rollers) / geometry.n_rollers
        along_cos, along_sin = _clearance_loss_phasor_m(geometry, misalignment)
        clearance = clearance - (
            np.cos(tau)[:, None] * along_cos[None, :] + np.sin(tau)[:, None] * along_sin[None, :]
        )
        if (clearance < 0.0).any():
            roller, thread = np.unravel_index(int(np.argmin(clearance)), shape)
            raise DomainError(
                f"screw misalignment closes the screw-roller clearance of roller {roller + 1}, "
                f"thread {thread + 1} to {clearance[roller, thread] * 1e6:.3f} um: the flanks "
                "would overlap"
            )
    centre = geometry.carrier_radius_m
    return Meshing(
        axial_clearance_screw_roller_m=_read_only(clearance),
        axial_clearance_roller_nut_m=_read_only(np.full(shape, contact.roller_nut_clearance_m)),
        contact_angle_screw_rad=math.atan2(contact.y_m, contact.x_m),
        contact_angle_roller_rad=math.atan2(contact.y_m, centre - contact.x_m),
        contact_radius_screw_m=math.hypot(contact.x_m, contact.y_m),
        contact_radius_roller_m=math.hypot(centre - contact.x_m, contact.y_m),
    )


def _speed_array(screw_speed_rad_s: ArrayLike) -> FloatArray:
    speed = np.asarray(screw_speed_rad_s, dtype=float)
    if not np.all(np.isfinite(speed)):
        raise ParameterError("screw_speed_rad_s", "must be finite")
    return speed


def carrier_speed_rad_s(geometry: Geometry, screw_speed_rad_s: ArrayLike) -> FloatArray:
    """Revolution speed of the rollers w_p = r_s w_s / (2 (r_s + r_r)) (004 eq. 30).

    Nut fixed in rotation; rolling without slip at both pitch points. 004 eq. 30 takes the
    contact radii r_si, r_rsi; the nominal ones differ from them by 0.06 % on 004's geometry.
    """
    return np.asarray(
        geometry.screw_radius_m
        * _speed_array(screw_speed_rad_s)
        / (2.0 * geometry.carrier_radius_m),
        dtype=float,
    )


def slip_speed_m_s(
    geometry: Geometry,
    meshing: Meshing,
    screw_speed_rad_s: ArrayLike,
    *,
    jammed: bool = False,
) -> FloatArray:
    """Magnitude of the screw-roller sliding velocity at the contact point (001 eq. 30).

    |v| = sqrt(r_sr^2 (w_s - w_p)^2 + (k r_rs w_p)^2
               - 2 r_sr r_rs k w_p (w_s - w_p) cos(theta_sr + theta_rs) + (w_s n_s p / 2 pi)^2)
    with w_p of 004 eq. 30 and the roller spin ratio k = (r_s + 2 r_r) / r_r (n_s of 001 eq. 30
    for a standard PRSM). ``jammed``: the roller does not spin relative to the carrier (paper
    002 section 2.3), k = 0. Same shape as ``screw_speed_rad_s``; proportional to |w_s|.
    """
    screw = _speed_array(screw_speed_rad_s)
    carrier = carrier_speed_rad_s(geometry, screw)
    spin_ratio = (
        0.0
        if jammed
        else ((geometry.screw_radius_m + 2.0 * geometry.roller_radius_m) / geometry.roller_radius_m)
    )
    screw_part = meshing.contact_radius_screw_m * (screw - carrier)
    roller_part = spin_ratio * meshing.contact_radius_roller_m * carrier
    cos_sum = math.cos(meshing.contact_angle_screw_rad + meshing.contact_angle_roller_rad)
    tangential_sq = screw_part**2 + roller_part**2 - 2.0 * screw_part * roller_part * cos_sum
    axial = screw * geometry.lead_m / (2.0 * math.pi)
    return np.asarray(np.sqrt(np.maximum(tangential_sq, 0.0) + axial**2), dtype=float)
