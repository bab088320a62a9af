"""Thread-by-thread load distribution over every roller of a PRSM.

Model (papers 000 eq. 7-25 and 004 eq. 14-22, written as one nonlinear system):

* Every roller i is a chain of n_threads nodes j (j = 0 is the loaded end). Screw, roller and
  nut segments between adjacent threads are axial springs of one pitch: the screw and nut
  shares are E A / (N p) per roller (004 eq. 16-17: their sections carry the loads of all N
  rollers; 000 eq. 17 writes p / (2 E A) per roller, 2N times stiffer, which we do not
  follow), the roller E A_r / p (004 writes 2p for the roller segment; one thread pitch is the
  physical length, docs/physics.md). In loading case 1 (screw in tension / nut in
  compression, 000 eq. 13; the 004 set-up) the screw load and the nut reaction enter at the
  same end; in case 2 (both in compression, 000 eq. 21) they enter at opposite ends. j counts
  from the screw's loaded end in both cases (000 eq. 21 numbers case 2 from the nut's, from 1:
  its thread j is our z - j). On every preset the loads fall along j in both cases, in case 2
  a little less (the far end carries more).
* With ``elastic_errors`` the screw segments of case 1 also twist under the driving torque
  T = F L / (2 pi eta) (000 eq. 2-5): the twist of a segment advances the thread by
  theta L / (2 pi), an extra axial compliance N p L^2 / (4 pi^2 eta G J) per roller share.
* Contacts are Hertzian (004 eq. 19): Q = (max(delta, 0) / K_h)^(3/2) with the normal approach
  delta as the unknown (smooth through contact loss). The normal approach of a contact is the
  relative axial displacement of the two bodies times sin(beta) cos(lambda), minus the
  unloaded axial clearance (004 eq. 21-22), plus cos(beta) times the screw's radial
  displacement towards the roller (000 eq. 7-9), at the roller position angle
  phi_i = theta + 2 pi i / N (000 eq. 8).
* Unknowns: both approaches at every thread of every roller, the axial offset of every roller,
  and the common rigid-body displacement of the screw relative to the nut (axial, and radial
  when the rollers are not symmetric). Equations: compatibility at every contact, axial
  equilibrium of every roller, axial equilibrium of the screw (000 eq. 12 second line) and its
  radial equilibrium (000 eq. 12 first line).

The system is solved by Newton's method with a backtracking line search on the whole system
(no shooting along the threads, whose growing mode ruins long rollers). Each roller's block is
solved directly and the few global unknowns by a Schur complement; all of it is vectorised
over a batch of load cases. The residual is checked and a :class:`ConvergenceError` raised if
it is not met. When there is no radial load and no roller-to-roller clearance difference, all
rollers carry the same load, and one roller is solved instead of N (``symmetric``).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache, partial
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from prsm_health.physics.errors import ConvergenceError, DomainError, ParameterError
from prsm_health.physics.geometry import Geometry
from prsm_health.physics.hertz import thread_contacts

FloatArray = NDArray[np.float64]

#: Nominal transmission efficiency used for the driving torque of the torsion term (000 eq. 3).
TORSION_EFFICIENCY = 0.9

#: Axial loads below this are treated as no load (zero forces, not solved). 1 mN is 1e-8 of
#: the papers' loads and far below what motor current resolves; below it the contact approaches
#: are 1e7 times smaller than micron clearances and the contact set is ill-determined. Radial
#: loads below it are none (no radial terms): the radial balance is solved relative to the
#: axial load, and one 1e-7 of it (7.8e-10 N against 6.6 mN, with a misalignment's clearances)
#: stalled Newton at a scaled residual of 5e-7.
NEGLIGIBLE_LOAD_N = 1e-3

#: Stiffness given to open contacts in the Newton matrix only, relative to a contact at the
#: mean load: keeps the matrix regular when few contacts touch; the solution is unchanged.
OPEN_CONTACT_STIFFNESS_RATIO = 1e-8

#: Relative round-off of a residual that sums a few dozen terms (64 machine epsilons).
ROUNDOFF = 64.0 * float(np.finfo(float).eps)

#: The Newton solve's limit on its scaled residual, and on its iterations.
RESIDUAL_TOLERANCE = 1e-11
MAX_ITERATIONS = 60


class LoadingCase(enum.IntEnum):
    """The two load paths of the downhole robot (paper 000, section 4.2)."""

    SCREW_TENSION_NUT_COMPRESSION = 1  # case 1: nut fixed, screw rotates and moves
    BOTH_COMPRESSION = 2  # case 2: screw only rotates, nut moves


@dataclass(frozen=True)
class LoadDistribution:
    """Solution for a batch of load cases (leading dims = the broadcast input shape).

    screw_roller_n, roller_nut_n: normal contact forces, shape (..., n_rollers, n_threads).
    roller_axial_load_n: axial load carried by each roller, shape (..., n_rollers).
    axial_offset_m: rigid axial displacement of the screw relative to the nut.
    radial_offset_m: radial displacement (x, y) of the screw relative to the nut, (..., 2).
    residual: largest scaled residual of the converged system (dimensionless).
    iterations: Newton iterations used.
    """

    screw_roller_n: FloatArray
    roller_nut_n: FloatArray
    roller_axial_load_n: FloatArray
    axial_offset_m: FloatArray
    radial_offset_m: FloatArray
    residual: float
    iterations: int


@dataclass(frozen=True)
class _ChainMatrices:
    """Compliance matrices of one roller chain: displacement per unit contact force."""

    screw_screw: FloatArray
    screw_nut: FloatArray
    nut_nut: FloatArray


@cache
def _chain_matrices(geometry: Geometry, case: LoadingCase, elastic_errors: bool) -> _ChainMatrices:
    """Influence matrices of the chain (node displacements from cumulative segment forces):
    the axial springs of 004 eq. 16-17 with the torsion of 000 eq. 2-5, loaded as 000 eq. 13
    (case 1) or eq. 21 (case 2).

    With the thread index j from the loaded end, the screw node displacement relative to
    node 0 is -sum_{k<j} (F - S_k) / k_s with S_k the transferred force, which gives
    M1[j, m] = min(j, m); the roller gives M2[j, m] = max(j - m, 0); the nut of case 2,
    supported at the far end, gives M3[j, m] = (z - 1) - max(j, m) (case 1: M3 = M1).
    """
    z = geometry.n_threads
    j, m = np.meshgrid(np.arange(z), np.arange(z), indexing="ij")
    m1 = np.minimum(j, m).astype(float)
    m2 = np.maximum(j - m, 0).astype(float)
    m3 = m1 if case is LoadingCase.SCREW_TENSION_NUT_COMPRESSION else (z - 1) - np.maximum(j, m)
    share = geometry.n_rollers * geometry.pitch_m
    screw_compliance = share / (geometry.screw.youngs_modulus_pa * geometry.screw_area_m2)
    if elastic_errors and case is LoadingCase.SCREW_TENSION_NUT_COMPRESSION:
        polar_moment = math.pi * geometry.screw_radius_m**4 / 2.0
        screw_compliance += (
            share
            * geometry.lead_m**2
            / (
                4.0
                * math.pi**2
                * TORSION_EFFICIENCY
                * geometry.screw.shear_modulus_pa
                * polar_moment
            )
        )
    roller_compliance = geometry.pitch_m / (
        geometry.roller.youngs_modulus_pa * geometry.roller_area_m2
    )
    nut_compliance = share / (geometry.nut.youngs_modulus_pa * geometry.nut_area_m2)
    c = geometry.axial_projection
    return _ChainMatrices(
        screw_screw=c * (m1 * screw_compliance - m2 * roller_compliance),
        screw_nut=c * m2 * roller_compliance,
        nut_nut=c * (np.asarray(m3, dtype=float) * nut_compliance - m2 * roller_compliance),
    )


def _as_batch(value: ArrayLike, name: str, *, minimum: float = 0.0) -> FloatArray:
    array = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(array)):
        raise ParameterError(name, "must be finite")
    if np.any(array < minimum):
        raise ParameterError(name, f"must be >= {minimum}")
    return array


def _clearance(value: ArrayLike | None, geometry: Geometry, name: str) -> FloatArray:
    shape = (geometry.n_rollers, geometry.n_threads)
    if value is None:
        return np.zeros(shape)
    array = np.asarray(value, dtype=float)
    if array.shape != shape or not np.all(np.isfinite(array)):
        raise ParameterError(name, f"must be a finite array of shape {shape}, got {array.shape}")
    return np.asarray(array - array.min(), dtype=np.float64)


def radial_capacity_ratio(
    geometry: Geometry, carrier_angle_rad: ArrayLike = 0.0, radial_load_angle_rad: ArrayLike = 0.0
) -> FloatArray:
    """Largest F_r / F_a that loaded-flank contacts can balance (000 eq. 12), at a carrier
    angle and a direction of the radial load (broadcast).

    A roller's contacts push the screw radially, towards the roller's position angle phi_i
    (000 eq. 8), by cos(beta) / (sin(beta) cos(lambda)) times their axial load. The radial
    forces the rollers can balance together are the non-negative combinations of these
    directions with the axial loads summing to F_a: a regular N-gon with its vertices at the
    rollers (at theta + 2 pi i / N, :attr:`Geometry.roller_angles_rad`). Along the load's
    direction psi it reaches cos(pi / N) / cos(delta), delta the angle from psi to the middle
    of the polygon's side it crosses, so

        F_r / F_a < cos(beta) / (sin(beta) cos(lambda)) * cos(pi / N) / cos(delta).

    The default angles put a roller in the load's direction: the largest value over all
    angles (cos(delta) = cos(pi / N)). Rollers on the far side unload (float) well before:
    with a cosine sharing, at F_r / F_a = 0.5 of it already.
    """
    sector = 2.0 * math.pi / geometry.n_rollers
    offset = np.mod(
        np.asarray(radial_load_angle_rad, dtype=np.float64)
        - np.asarray(carrier_angle_rad, dtype=np.float64),
        sector,
    )
    polygon = math.cos(sector / 2.0) / np.cos(offset - sector / 2.0)
    return np.asarray(
        geometry.radial_projection / geometry.axial_projection * polygon, dtype=np.float64
    )


def solve_load_distribution(
    geometry: Geometry,
    axial_load_n: ArrayLike,
    *,
    radial_load_n: ArrayLike = 0.0,
    radial_load_angle_rad: ArrayLike = 0.0,
    carrier_angle_rad: ArrayLike = 0.0,
    clearance_screw_roller_m: ArrayLike | None = None,
    clearance_roller_nut_m: ArrayLike | None = None,
    case: LoadingCase = LoadingCase.SCREW_TENSION_NUT_COMPRESSION,
    elastic_errors: bool = False,
) -> LoadDistribution:
    """Normal contact forces on every thread of every roller (see the module docstring).

    ``axial_load_n``, ``radial_load_n``, ``radial_load_angle_rad`` (direction of the radial
    load on the screw) and ``carrier_angle_rad`` (theta of 000 eq. 8) broadcast to a batch.
    Clearances are the unloaded axial clearances per (roller, thread) from
    :func:`prsm_health.physics.meshing.meshing`; only their differences matter.

    Raises :class:`DomainError` when no loaded-flank contact state balances the loads (radial
    load beyond the contact-loss limit, or radial load without axial load).
    """
    axial, radial, load_angle, carrier = np.broadcast_arrays(
        _as_batch(axial_load_n, "axial_load_n"),
        _as_batch(radial_load_n, "radial_load_n"),
        _as_batch(radial_load_angle_rad, "radial_load_angle_rad", minimum=-np.inf),
        _as_batch(carrier_angle_rad, "carrier_angle_rad", minimum=-np.inf),
    )
    capacity = axial * radial_capacity_ratio(geometry, carrier, load_angle)
    if np.any((radial >= capacity) & (radial > 0.0)):
        worst = float(np.max(radial - capacity))
        raise DomainError(
            f"radial load exceeds what the loaded flanks can balance at this carrier angle "
            f"(radial_capacity_ratio) by {worst:.6g} N (a radial load without axial load, or "
            "larger than that, needs the opposite flank, which is not modelled)"
        )
    radial = np.where(radial > NEGLIGIBLE_LOAD_N, radial, 0.0)
    batch_shape = axial.shape
    g_sr = _clearance(clearance_screw_roller_m, geometry, "clearance_screw_roller_m")
    g_rn = _clearance(clearance_roller_nut_m, geometry, "clearance_roller_nut_m")
    symmetric = not np.any(radial > 0.0) and not np.any(g_sr + g_rn)
    n, z = geometry.n_rollers, geometry.n_threads
    flat = axial.reshape(-1)
    size = flat.shape[0]
    q_s = np.zeros((size, n, z))
    q_n = np.zeros((size, n, z))
    axial_offset = np.zeros(size)
    radial_offset = np.zeros((size, 2))
    residual, iterations = 0.0, 0
    loaded = flat > NEGLIGIBLE_LOAD_N  # unloaded members are exactly zero: skip them
    if np.any(loaded):
        solve = partial(
            _newton,
            geometry,
            flat[loaded],
            radial.reshape(-1)[loaded],
            load_angle.reshape(-1)[loaded],
            carrier.reshape(-1)[loaded],
            chain=_chain_matrices(geometry, case, elastic_errors),
            symmetric=symmetric,
        )
        try:
            solved = solve(g_sr, g_rn)
        except ConvergenceError:
            if symmetric:
                raise
            solved = _clearance_continuation(solve, g_sr, g_rn)
        q_s[loaded], q_n[loaded] = solved.screw_roller_n, solved.roller_nut_n
        axial_offset[loaded] = solved.state.glob[:, 0]
        if not symmetric:
            radial_offset[loaded] = solved.state.glob[:, 1:]
        residual, iterations = solved.residual, solved.iterations
    return LoadDistribution(
        screw_roller_n=q_s.reshape(*batch_shape, n, z),
        roller_nut_n=q_n.reshape(*batch_shape, n, z),
        roller_axial_load_n=(q_s.sum(axis=-1) * geometry.axial_projection).reshape(*batch_shape, n),
        axial_offset_m=axial_offset.reshape(batch_shape),
        radial_offset_m=radial_offset.reshape(*batch_shape, 2),
        residual=residual,
        iterations=iterations,
    )


class _State(NamedTuple):
    """Newton unknowns: approaches (batch, rollers, threads), roller and global offsets."""

    d_s: FloatArray
    d_n: FloatArray
    a: FloatArray
    glob: FloatArray


@dataclass(frozen=True)
class _Solved:
    state: _State
    screw_roller_n: FloatArray
    roller_nut_n: FloatArray
    residual: float
    iterations: int


#: Clearance scales of the continuation used when Newton fails from the cold start.
CONTINUATION_STEPS = 8


def _clearance_continuation(
    solve: Callable[..., _Solved], g_sr: FloatArray, g_rn: FloatArray
) -> _Solved:
    """Solve with the clearances grown from zero to their value, warm-starting each step.

    Without clearance differences the system is smooth; growing them opens contacts one by
    one instead of asking Newton to find the contact set at once (small loads against the
    clearances of a misalignment). Raises ConvergenceError if a step fails.
    """
    solved = solve(0.0 * g_sr, 0.0 * g_rn)
    iterations = solved.iterations
    for scale in np.linspace(0.0, 1.0, CONTINUATION_STEPS + 1)[1:]:
        solved = solve(scale * g_sr, scale * g_rn, start=solved.state)
        iterations += solved.iterations
    return _Solved(
        solved.state, solved.screw_roller_n, solved.roller_nut_n, solved.residual, iterations
    )


def _newton(
    geometry: Geometry,
    axial: FloatArray,
    radial: FloatArray,
    load_angle: FloatArray,
    carrier: FloatArray,
    g_sr: FloatArray,
    g_rn: FloatArray,
    *,
    chain: _ChainMatrices,
    symmetric: bool,
    start: _State | None = None,
) -> _Solved:
    """Damped Newton on the whole system from ``start`` (or a uniform-load guess): contact
    compatibility (004 eq. 19, 21-22; 000 eq. 9), each roller's axial equilibrium and the
    screw's axial and radial equilibrium (000 eq. 12), as the module docstring says."""
    contacts = thread_contacts(geometry)
    k_sr = contacts.screw_roller.deflection_constant
    k_rn = contacts.roller_nut.deflection_constant
    c = geometry.axial_projection
    cos_beta = geometry.radial_projection
    z = geometry.n_threads
    rollers = 1 if symmetric else geometry.n_rollers
    n_global = 1 if symmetric else 3
    batch = axial.shape[0]
    # Roller unit vectors n_i (batch, rollers, 2) at phi_i = theta + tau_i (000 eq. 8).
    phi = carrier[:, None] + np.asarray(geometry.roller_angles_rad)[None, :rollers]
    unit = np.stack((np.cos(phi), np.sin(phi)), axis=-1)
    target_axial = axial / geometry.n_rollers if symmetric else axial
    target_radial = radial[:, None] * np.stack((np.cos(load_angle), np.sin(load_angle)), axis=-1)
    clear_s = np.broadcast_to(g_sr[:rollers], (batch, rollers, z))
    clear_n = np.broadcast_to(g_rn[:rollers], (batch, rollers, z))

    # Scales: mean contact load and its approach make every equation dimensionless.
    q_ref = axial / (c * geometry.n_rollers * z)
    delta_ref = k_sr * q_ref ** (2.0 / 3.0)
    force_scale = 1.0 / (q_ref * z)  # per-roller sums of contact forces

    def loads(delta: FloatArray, k: float) -> tuple[FloatArray, FloatArray]:
        root = np.sqrt(np.maximum(delta, 0.0)) / k**1.5
        return root * np.maximum(delta, 0.0), 1.5 * root

    def residuals(
        d_s: FloatArray, d_n: FloatArray, a: FloatArray, glob: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        q_s, _ = loads(d_s, k_sr)
        q_n, _ = loads(d_n, k_rn)
        approach = 0.0 if symmetric else unit @ glob[:, 1:, None]
        r_s = (
            d_s / c
            - a[..., None]
            + q_s @ chain.screw_screw.T
            + q_n @ chain.screw_nut.T
            + clear_s
            - cos_beta / c * approach
        )
        r_n = (
            d_n / c
            + a[..., None]
            - glob[:, :1, None]
            + q_s @ chain.screw_nut.T
            + q_n @ chain.nut_nut.T
            + clear_n
        )
        roller_sum = q_s.sum(axis=-1)
        r_eq = (roller_sum - q_n.sum(axis=-1)) * force_scale[:, None]
        r_glob = np.empty((batch, n_global))
        r_glob[:, 0] = (c * roller_sum.sum(axis=-1) - target_axial) * force_scale / c
        if not symmetric:
            r_glob[:, 1:] = (
                cos_beta * (roller_sum[:, None, :] @ unit)[:, 0] - target_radial
            ) * force_scale[:, None]
        return r_s, r_n, r_eq, r_glob

    # Compatibility residuals sum clearances that can be 1e4 times the approaches at tiny
    # loads; their round-off floor joins the scale, so the tolerance stays reachable.
    clearance_span = c * max(float(np.ptp(g_sr)), float(np.ptp(g_rn)))
    kin_scale = delta_ref + ROUNDOFF * (clearance_span + delta_ref) / RESIDUAL_TOLERANCE

    def norm(parts: tuple[FloatArray, FloatArray, FloatArray, FloatArray]) -> FloatArray:
        """Largest scaled residual of each batch member (the convergence test)."""
        r_s, r_n, r_eq, r_glob = parts
        kin = np.maximum(np.abs(r_s).max(axis=(1, 2)), np.abs(r_n).max(axis=(1, 2))) * c
        worst = np.maximum(kin / kin_scale, np.abs(r_eq).max(axis=1))
        return np.asarray(np.maximum(worst, np.abs(r_glob).max(axis=1)), dtype=np.float64)

    def merit(parts: tuple[FloatArray, FloatArray, FloatArray, FloatArray]) -> FloatArray:
        """Sum of squared scaled residuals: Newton's step is a descent direction for it."""
        r_s, r_n, r_eq, r_glob = parts
        kin = (np.square(r_s).sum(axis=(1, 2)) + np.square(r_n).sum(axis=(1, 2))) * c**2
        forces = np.square(r_eq).sum(axis=1) + np.square(r_glob).sum(axis=1)
        return np.asarray(kin / kin_scale**2 + forces, dtype=np.float64)

    # Initial guess: uniform loads; offsets that zero the mean compatibility residual.
    # Start from uniform loads, less the clearances: at loads whose approaches are small
    # against the clearances only the tightest contacts start (and end) closed.
    d_s = (k_sr * q_ref ** (2.0 / 3.0))[:, None, None] - c * clear_s
    d_n = (k_rn * q_ref ** (2.0 / 3.0))[:, None, None] - c * clear_n
    # A vanishing stiffness for open contacts keeps the Newton matrix regular when few
    # contacts touch; it is in the Jacobian only, so the converged solution is unchanged.
    open_stiffness = OPEN_CONTACT_STIFFNESS_RATIO * 1.5 * np.sqrt(delta_ref)[:, None, None]
    open_stiffness_s = open_stiffness / k_sr**1.5
    open_stiffness_n = open_stiffness / k_rn**1.5
    if start is None:
        a = np.zeros((batch, rollers))
        glob = np.zeros((batch, n_global))
        r_s, r_n, r_eq, r_glob = residuals(d_s, d_n, a, glob)
        # The offsets enter the compatibility residuals linearly (r_s - a, r_n + a - offset).
        a = r_s.mean(axis=-1)
        glob[:, 0] = (r_n.mean(axis=-1) + a).mean(axis=-1)
        parts = (r_s - a[..., None], r_n + a[..., None] - glob[:, :1, None], r_eq, r_glob)
    else:
        d_s, d_n, a, glob = (np.array(x) for x in start)
        parts = residuals(d_s, d_n, a, glob)
    size = 2 * z + 1
    eye = np.eye(z) / c
    # Jacobian entries that do not change between iterations.
    jac = np.zeros((batch, rollers, size, size))
    jac[..., :z, -1] = -1.0
    jac[..., z : 2 * z, -1] = 1.0
    border = np.zeros((batch, rollers, size, n_global))
    border[..., z : 2 * z, 0] = -1.0
    if not symmetric:
        border[..., :z, 1:] = -cos_beta / c * unit[:, :, None, :]
    c_rows = np.zeros((batch, rollers, n_global, size))
    error = norm(parts)
    current = merit(parts)
    iterations = 0
    while np.any(error > RESIDUAL_TOLERANCE):
        if iterations == MAX_ITERATIONS:
            raise ConvergenceError(
                f"load distribution did not converge in {MAX_ITERATIONS} iterations: "
                f"scaled residual {float(error.max()):.3g} > {RESIDUAL_TOLERANCE:g}"
            )
        iterations += 1
        r_s, r_n, r_eq, r_glob = parts
        _, dq_s = loads(d_s, k_sr)
        _, dq_n = loads(d_n, k_rn)
        dq_s += open_stiffness_s
        dq_n += open_stiffness_n
        np.multiply(chain.screw_screw, dq_s[..., None, :], out=jac[..., :z, :z])
        np.multiply(chain.screw_nut, dq_n[..., None, :], out=jac[..., :z, z : 2 * z])
        np.multiply(chain.screw_nut, dq_s[..., None, :], out=jac[..., z : 2 * z, :z])
        np.multiply(chain.nut_nut, dq_n[..., None, :], out=jac[..., z : 2 * z, z : 2 * z])
        jac[..., :z, :z] += eye
        jac[..., z : 2 * z, z : 2 * z] += eye
        weights = dq_s * force_scale[:, None, None]
        jac[..., -1, :z] = weights
        jac[..., -1, z : 2 * z] = -dq_n * force_scale[:, None, None]
        # A roller with no loaded contact floats: keep it where it is (Jacobian only).
        jac[..., -1, -1] = -1e-12 * (1.0 + np.abs(jac[..., -1, :-1]).sum(axis=-1))
        # The border B holds the derivatives of the roller equations by the global unknowns.
        rhs = np.concatenate(
            (np.concatenate((r_s, r_n, r_eq[..., None]), axis=-1)[..., None], border), axis=-1
        )
        solved = np.linalg.solve(jac, rhs)  # A^-1 [r, B]
        # Global rows C: d(global residual)/d(delta_s of each roller).
        c_rows[..., 0, :z] = weights
        if not symmetric:
            c_rows[..., 1:, :z] = cos_beta * unit[..., :, None] * weights[..., None, :]
        schur = (c_rows @ solved[..., 1:]).sum(axis=1)
        # [A B; C 0][dx; dy] = -[r; r_g]  =>  (C A^-1 B) dy = r_g - C A^-1 r.
        schur_rhs = r_glob - (c_rows @ solved[..., :1]).sum(axis=1)[..., 0]
        step_glob = np.linalg.solve(schur, schur_rhs[..., None])[..., 0]
        step = -solved[..., 0] - (solved[..., 1:] @ step_glob[:, None, :, None])[..., 0]
        # Backtracking line search on the scaled residual norm, per batch member.
        alpha = np.ones(batch)
        for _ in range(30):
            trial = (
                d_s + alpha[:, None, None] * step[..., :z],
                d_n + alpha[:, None, None] * step[..., z : 2 * z],
                a + alpha[:, None] * step[..., -1],
                glob + alpha[:, None] * step_glob,
            )
            trial_parts = residuals(*trial)
            trial_merit = merit(trial_parts)
            worse = trial_merit > (1.0 - 1e-4 * alpha) * current
            if not np.any(worse & (error > RESIDUAL_TOLERANCE)):
                break
            alpha = np.where(worse, alpha * 0.5, alpha)
        d_s, d_n, a, glob = trial
        parts, current = trial_parts, trial_merit
        error = norm(parts)

    return _Solved(
        state=_State(d_s, d_n, a, glob),
        screw_roller_n=loads(d_s, k_sr)[0],
        roller_nut_n=loads(d_n, k_rn)[0],
        residual=float(error.max(initial=0.0)),
        iterations=iterations,
    )
