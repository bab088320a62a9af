"""Per-roller physics of a PRSM, tabulated over axial load, radial-load ratio and roller angle.

The truth simulator (and, averaged over the angle, the estimator) needs for every roller at
every sample its friction torque, wear rate and peak contact force. Solving the thread load
distribution (papers 000 eq. 7-25, 004 eq. 14-22) at every sample costs about 1-4 ms; this
module solves it once on a grid and interpolates.

What a roller's values depend on. For one preset, misalignment and loading case, the contact
loads of roller i depend on the axial load F_a, the radial load F_r and the carrier angle
theta. Roller i sits at the position angle phi_i = theta + 2 pi (i - 1) / N (paper 000 eq. 8),
measured in the fixed frame from the radial-load direction (the x axis, about which the
misalignment tilts of paper 004 eq. 3 are also given). The radial load keeps its direction
in space and the misaligned clearances turn with the carrier (004 eq. 4), so the
configuration at theta + 2 pi / N is that at theta with the rollers relabelled: each roller's
values are one function of its own angle phi, of F_a and of rho = F_r / F_a. The table fills
that function by solving a batch of carrier angles in [0, 2 pi / N) and collecting all rollers.
Without misalignment the model is also symmetric about the radial-load axis (000 eq. 12 has
only cos/sin projections), so half a sector is solved and mirrored. Axes are skipped when
not needed: no rho axis without radial load, no phi axis when additionally aligned (all
rollers carry the same load).

Every quantity is a power law of the contact loads Q (friction: Q^(4/3), Q^(5/3), Q^0.47, Q;
Archard wear Q^(2/3); peak force Q). The table stores the "equivalent load" (value)^(1/e) / F_a,
e the exponent of the quantity's main term, which is nearly constant in F_a and nearly linear
in rho and in the roller's angle (as the roller's load is); it is interpolated linearly in
ln F_a, in rho and (periodically) in phi, and raised back to the power e. Below the grid the
power law is extrapolated (exactly 0 at F_a = 0); above it, or beyond the largest rho, the
lookup refuses.

Measured error of the default :class:`TableGrid` on dong2022-downhole, largest relative
deviation from :func:`roller_values` over 600 random off-grid points (F_a log-uniform in
0.1-1 x 55 kN, rho uniform up to 0.5, any carrier angle; ``bench/bench_roller_table.py``):

============================  ========  ==========  ========  ==========
configuration                 friction  one jammed  wear      peak force
============================  ========  ==========  ========  ==========
aligned, radial (case 1, 2)   1.6e-4    5.4e-3      3.7e-3    1.4e-3
aligned, axial only           4.6e-5    7.7e-6      3.0e-3    9.1e-4
2' tilt, axial only           8.0e-4    4.4e-3      1.3e-3    5.3e-3
2' tilt, radial               7.9e-4    6.0e-2      3.1e-3    4.9e-3
============================  ========  ==========  ========  ==========

friction: total friction torque at 300 rpm, all rollers healthy; one jammed: the same with
any one roller jammed (its sliding torque follows its own load, which varies fastest where it
is light); wear: total wear rate (the fractal law has regime kinks in Q); peak force: the
largest contact force over all rollers (fatigue). Builds take about 1 s per loading case with
radial load and no tilt, 8 s with both (with a tilt the load axis needs more points).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from functools import cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

from prsm_health.physics.errors import DomainError, ParameterError
from prsm_health.physics.friction import (
    VISCOUS_LOAD_EXPONENT,
    VISCOUS_SPEED_EXPONENT,
    friction_torque,
)
from prsm_health.physics.geometry import (
    Geometry,
    Misalignment,
    require,
    require_integer,
    require_ranges,
)
from prsm_health.physics.load_distribution import (
    LoadingCase,
    radial_capacity_ratio,
    solve_load_distribution,
)
from prsm_health.physics.meshing import meshing, slip_speed_m_s
from prsm_health.physics.presets import Preset
from prsm_health.physics.wear import wear_depth_rate_m_per_s

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class RollerValues:
    """Physics of each roller at given loads; every array has shape (..., n_rollers), SI.

    rolling_torque_nm: hysteresis + spin + differential sliding of the roller when healthy,
        i.e. its standstill (breakaway) friction torque on the screw (paper 002 eq. 2-4, 12-13).
    viscous_torque_nm: its viscous rolling torque at |omega_s| = 1 rad/s (002 eq. 5-11); at
        other speeds it scales as |omega_s|^0.66.
    jammed_torque_nm: its sliding torque when jammed, replacing the two above (002 eq. 15-16).
    wear_m_per_rad, jammed_wear_m_per_rad: its share of the precision-loss rate per unit
        |omega_s| [m/s per rad/s], healthy and jammed (004 eq. 34-35, 001 eq. 34-38; the slip
        speed of 001 eq. 30 is proportional to |omega_s|).
    peak_contact_force_n: its largest screw-roller contact force (fatigue, 000 eq. 29).
    """

    rolling_torque_nm: FloatArray
    viscous_torque_nm: FloatArray
    jammed_torque_nm: FloatArray
    wear_m_per_rad: FloatArray
    jammed_wear_m_per_rad: FloatArray
    peak_contact_force_n: FloatArray

    def friction_torque_nm(self, screw_speed_rad_s: ArrayLike, jammed: ArrayLike) -> FloatArray:
        """Friction torque magnitude of each roller (002 eq. 12-18), shape (..., n_rollers).

        ``screw_speed_rad_s`` broadcasts against the rollers (pass shape (..., 1)); ``jammed``
        is a bool mask broadcasting to (..., n_rollers).
        """
        speed_factor = np.abs(np.asarray(screw_speed_rad_s, dtype=np.float64))
        healthy = self.rolling_torque_nm + self.viscous_torque_nm * (
            speed_factor**VISCOUS_SPEED_EXPONENT
        )
        return np.asarray(np.where(jammed, self.jammed_torque_nm, healthy), dtype=np.float64)

    def wear_rate_m_per_s(self, screw_speed_rad_s: ArrayLike, jammed: ArrayLike) -> FloatArray:
        """Each roller's precision-loss rate [m/s] at ``screw_speed_rad_s`` (shape as above):
        the wear per radian of the screw tabulated from 004 eq. 33-35 / 001 eq. 32-38 (a
        jammed roller's with its full slip speed, meshing.py) times the speed."""
        per_rad = np.where(jammed, self.jammed_wear_m_per_rad, self.wear_m_per_rad)
        speed = np.abs(np.asarray(screw_speed_rad_s, dtype=np.float64))
        return np.asarray(per_rad * speed, dtype=np.float64)


#: Load exponent of each :class:`RollerValues` field's main term (the table stores value / F^e).
_LOAD_EXPONENTS = np.array([4.0 / 3.0, VISCOUS_LOAD_EXPONENT, 1.0, 2.0 / 3.0, 2.0 / 3.0, 1.0])
_N_QUANTITIES = len(_LOAD_EXPONENTS)


def _float_batch(value: ArrayLike, name: str) -> FloatArray:
    array = np.asarray(value, dtype=np.float64)
    if not np.isfinite(array).all():
        raise ParameterError(name, "must be finite")
    return array


def roller_values(
    preset: Preset,
    axial_load_n: ArrayLike,
    *,
    radial_load_n: ArrayLike = 0.0,
    carrier_angle_rad: ArrayLike = 0.0,
    misalignment: Misalignment | None = None,
    case: LoadingCase = LoadingCase.SCREW_TENSION_NUT_COMPRESSION,
) -> RollerValues:
    """Each roller's values straight from the physics core (no table), shape (..., n_rollers).

    ``axial_load_n`` (>= 0), ``radial_load_n`` (along x) and ``carrier_angle_rad`` broadcast to
    a batch. Loads: :func:`solve_load_distribution` with the clearances of
    :func:`meshing` at each carrier angle (000 eq. 7-25, 004 eq. 1-22); torques:
    :func:`friction_torque` (002 eq. 2-18); wear: :func:`wear_depth_rate_m_per_s` at the slip
    speed of :func:`slip_speed_m_s` for 1 rad/s (001 eq. 30, 004 eq. 34). With a misalignment
    the clearances differ per carrier angle, so each distinct angle is one solve.
    """
    geometry = preset.geometry
    tilt = misalignment if misalignment is not None else Misalignment()
    axial, radial, carrier = np.broadcast_arrays(
        _float_batch(axial_load_n, "axial_load_n"),
        _float_batch(radial_load_n, "radial_load_n"),
        _float_batch(carrier_angle_rad, "carrier_angle_rad"),
    )
    if tilt.is_aligned:
        loads = solve_load_distribution(
            geometry, axial, radial_load_n=radial, carrier_angle_rad=carrier, case=case
        )
        screw_roller, roller_nut = loads.screw_roller_n, loads.roller_nut_n
    else:
        contact_shape = (*axial.shape, geometry.n_rollers, geometry.n_threads)
        screw_roller, roller_nut = np.empty(contact_shape), np.empty(contact_shape)
        angles, inverse = np.unique(carrier, return_inverse=True)
        inverse = inverse.reshape(axial.shape)
        for k, angle in enumerate(angles):
            mesh = meshing(geometry, tilt, carrier_angle_rad=float(angle))
            members = inverse == k
            loads = solve_load_distribution(
                geometry,
                axial[members],
                radial_load_n=radial[members],
                carrier_angle_rad=float(angle),
                clearance_screw_roller_m=mesh.axial_clearance_screw_roller_m,
                clearance_roller_nut_m=mesh.axial_clearance_roller_nut_m,
                case=case,
            )
            screw_roller[members], roller_nut[members] = loads.screw_roller_n, loads.roller_nut_n
    rolling = friction_torque(geometry, preset.friction, screw_roller, roller_nut, 0.0)
    viscous = friction_torque(geometry, preset.friction, screw_roller, roller_nut, 1.0)
    jammed = friction_torque(
        geometry, preset.friction, screw_roller, roller_nut, 0.0, jammed=geometry.n_rollers
    )
    # Contact points (hence slip speeds) are the aligned ones (meshing.py).
    aligned = meshing(geometry, Misalignment())
    wear = [
        wear_depth_rate_m_per_s(
            geometry,
            preset.wear,
            screw_roller,
            slip_speed_m_s(geometry, aligned, 1.0, jammed=seized),
        ).sum(axis=-1)
        for seized in (False, True)
    ]
    return RollerValues(
        rolling_torque_nm=rolling.hysteresis_nm + rolling.spin_nm + rolling.differential_nm,
        viscous_torque_nm=viscous.viscous_nm,
        jammed_torque_nm=jammed.jammed_sliding_nm,
        wear_m_per_rad=np.asarray(wear[0], dtype=np.float64),
        jammed_wear_m_per_rad=np.asarray(wear[1], dtype=np.float64),
        peak_contact_force_n=np.asarray(screw_roller.max(axis=-1), dtype=np.float64),
    )


@dataclass(frozen=True, kw_only=True)
class TableGrid:
    """Grid of a :class:`RollerTable`; the default's measured error is in the module docstring.

    load_min_fraction, load_max_factor: the axial-load axis runs log-spaced from
        load_min_fraction to load_max_factor times the preset's largest axial load.
    loads, misaligned_loads: points on that axis without and with a misalignment (whose
        contacts close one by one as the load grows: less of a power law at small loads).
    ratio_max_fraction: the rho axis runs from 0 to this fraction of the radial capacity
        (:func:`radial_capacity_ratio`). At 0.5 every roller still carries load; beyond about
        0.6 the far rollers unload and the load piles onto a few (the model ends at 1), which
        linear interpolation in rho follows poorly.
    ratios: points on the rho axis.
    angles_per_sector: carrier angles solved per roller spacing 2 pi / N (the phi axis has
        N times as many points per revolution).
    """

    load_min_fraction: float = 0.01
    load_max_factor: float = 3.0
    loads: int = 10
    misaligned_loads: int = 16
    ratio_max_fraction: float = 0.5
    ratios: int = 9
    angles_per_sector: int = 8

    def __post_init__(self) -> None:
        positive = ("load_min_fraction", "load_max_factor", "ratio_max_fraction")
        require_ranges(self, "grid", dict.fromkeys(positive))
        require(
            self.ratio_max_fraction < 1.0,
            "grid.ratio_max_fraction",
            f"must be < 1, got {self.ratio_max_fraction:g}",
        )
        require(
            self.load_min_fraction < self.load_max_factor,
            "grid.load_max_factor",
            f"must be > load_min_fraction {self.load_min_fraction:g}, got {self.load_max_factor:g}",
        )
        for name in ("loads", "misaligned_loads", "ratios", "angles_per_sector"):
            require_integer(getattr(self, name), f"grid.{name}", 2)

    def max_radial_ratio(self, geometry: Geometry) -> float:
        """Largest F_r / F_a of the rho axis: ratio_max_fraction of the radial capacity."""
        return self.ratio_max_fraction * float(radial_capacity_ratio(geometry))


@dataclass(frozen=True, eq=False)
class RollerTable:
    """:class:`RollerValues` of every roller angle on a grid, for one preset, tilt and case.

    load_grid_n: the log-spaced axial loads. ratio_grid: the radial ratios rho (just [0] when
    the table has no radial axis). angles: grid points per revolution of phi (1 when all
    rollers are equal). normalized: value / F_a^e, shape (loads, ratios, angles, quantities).
    Build with :func:`roller_table`; evaluate with :meth:`lookup`.
    """

    preset: Preset
    misalignment: Misalignment
    case: LoadingCase
    load_grid_n: FloatArray
    ratio_grid: FloatArray
    angles: int
    normalized: FloatArray

    @property
    def max_axial_load_n(self) -> float:
        """Largest axial load the table covers [N]."""
        return float(self.load_grid_n[-1])

    @property
    def max_radial_ratio(self) -> float:
        """Largest F_r / F_a the table covers (0 without a radial axis)."""
        return float(self.ratio_grid[-1])

    def lookup(
        self, axial_load_n: ArrayLike, radial_ratio: ArrayLike, angle_rad: ArrayLike
    ) -> RollerValues:
        """Interpolated values at the broadcast of the three inputs (one entry per roller).

        axial_load_n: F_a in [0, max_axial_load_n]. radial_ratio: rho = F_r / F_a in
        [0, max_radial_ratio]. angle_rad: the roller's position angle phi from the
        radial-load direction (any real; periodic). Pass rollers along the last axis, e.g.
        F (n, 1), rho (n, 1), phi (n, n_rollers). Returns arrays of the broadcast shape.
        """
        load = _float_batch(axial_load_n, "axial_load_n")
        ratio = _float_batch(radial_ratio, "radial_ratio")
        angle = _float_batch(angle_rad, "angle_rad")
        if np.any(load < 0.0):
            raise ParameterError("axial_load_n", "must be >= 0")
        if np.any(load > self.max_axial_load_n):
            raise DomainError(
                f"axial_load_n: {float(load.max()):.6g} N is above the table's "
                f"{self.max_axial_load_n:.6g} N (TableGrid.load_max_factor)"
            )
        if np.any(ratio < 0.0) or np.any(ratio > self.max_radial_ratio):
            raise DomainError(
                f"radial_ratio: must be in [0, {self.max_radial_ratio:.6g}] for this table, "
                f"got [{float(ratio.min()):.6g}, {float(ratio.max()):.6g}]"
            )
        shape = np.broadcast_shapes(load.shape, ratio.shape, angle.shape)
        n_loads, n_ratios = len(self.load_grid_n), len(self.ratio_grid)
        corners: list[list[tuple[NDArray[np.intp] | int, FloatArray | float]]] = []
        # ln F_a: below the grid the normalised value is held, i.e. the power law continues.
        steps = np.log(np.maximum(load, self.load_grid_n[0]) / self.load_grid_n[0])
        corners.append(
            _linear(steps / math.log(self.load_grid_n[1] / self.load_grid_n[0]), n_loads)
        )
        if n_ratios > 1:
            corners.append(_linear(ratio / float(self.ratio_grid[1]), n_ratios))
        else:
            corners.append([(0, 1.0)])
        if self.angles > 1:
            corners.append(_periodic(angle * (self.angles / (2.0 * math.pi)), self.angles))
        else:
            corners.append([(0, 1.0)])
        flat = self.normalized.reshape(-1, _N_QUANTITIES)
        result = np.zeros((*shape, _N_QUANTITIES))
        for i, w_load in corners[0]:
            for j, w_ratio in corners[1]:
                for k, w_angle in corners[2]:
                    index = (np.multiply(i, n_ratios) + j) * self.angles + k
                    weight = np.multiply(np.multiply(w_load, w_ratio), w_angle)
                    result += np.asarray(weight)[..., np.newaxis] * flat[index]
        result *= load[..., np.newaxis]
        np.power(result, _LOAD_EXPONENTS, out=result)
        return RollerValues(*(result[..., q] for q in range(_N_QUANTITIES)))


def _linear(
    position: FloatArray, size: int
) -> list[tuple[NDArray[np.intp] | int, FloatArray | float]]:
    """Lower/upper grid index and weight of a position in grid steps (inside [0, size - 1])."""
    lower = np.minimum(position.astype(np.intp), size - 2)
    upper_weight = position - lower
    return [(lower, 1.0 - upper_weight), (lower + 1, upper_weight)]


def _periodic(
    position: FloatArray, size: int
) -> list[tuple[NDArray[np.intp] | int, FloatArray | float]]:
    """Like :func:`_linear` on a periodic grid of ``size`` points per period."""
    floor = np.floor(position)
    lower = floor.astype(np.intp) % size
    upper_weight = position - floor
    return [(lower, 1.0 - upper_weight), ((lower + 1) % size, upper_weight)]


@cache
def roller_table(
    preset: Preset,
    misalignment: Misalignment,
    case: LoadingCase,
    *,
    radial: bool,
    grid: TableGrid | None = None,
) -> RollerTable:
    """Build (once per arguments; cached) the table of :func:`roller_values` on ``grid``.

    ``radial``: whether the table needs a rho axis (a scene with radial load). The build is
    one batched solve per carrier angle solved (see the module docstring).
    """
    grid = grid if grid is not None else TableGrid()
    geometry = preset.geometry
    n_rollers = geometry.n_rollers
    largest = preset.largest_axial_load_n
    count = grid.loads if misalignment.is_aligned else grid.misaligned_loads
    loads = np.geomspace(grid.load_min_fraction * largest, grid.load_max_factor * largest, count)
    ratios = (
        np.linspace(0.0, grid.max_radial_ratio(geometry), grid.ratios) if radial else np.zeros(1)
    )
    if not radial and misalignment.is_aligned:
        values = roller_values(preset, loads, case=case)
        table = np.stack([getattr(values, f.name)[:, :1] for f in fields(RollerValues)], axis=-1)
        table = table[:, np.newaxis]  # (loads, 1 ratio, 1 angle, quantities)
        angles = 1
    else:
        per_sector = grid.angles_per_sector
        angles = n_rollers * per_sector
        mirror = misalignment.is_aligned  # symmetric about the radial-load axis
        solved = np.arange(per_sector // 2 + 1 if mirror else per_sector)
        load_mesh, ratio_mesh, angle_mesh = np.meshgrid(
            loads, ratios, solved * (2.0 * math.pi / angles), indexing="ij"
        )
        values = roller_values(
            preset,
            load_mesh,
            radial_load_n=ratio_mesh * load_mesh,
            carrier_angle_rad=angle_mesh,
            misalignment=misalignment,
            case=case,
        )
        stacked = np.stack([getattr(values, f.name) for f in fields(RollerValues)], axis=-1)
        table = np.empty((len(loads), len(ratios), angles, _N_QUANTITIES))
        # Roller i at carrier angle theta_j sits at phi = theta_j + 2 pi i / N.
        index = solved[:, np.newaxis] + per_sector * np.arange(n_rollers)[np.newaxis, :]
        table[:, :, index] = stacked
        if mirror:
            filled = np.zeros(angles, dtype=bool)
            filled[index.ravel()] = True
            missing = np.flatnonzero(~filled)
            table[:, :, missing] = table[:, :, (-missing) % angles]
    normalized = table ** (1.0 / _LOAD_EXPONENTS) / loads[:, np.newaxis, np.newaxis, np.newaxis]
    normalized.setflags(write=False)
    return RollerTable(
        preset=preset,
        misalignment=misalignment,
        case=case,
        load_grid_n=loads,
        ratio_grid=ratios,
        angles=angles,
        normalized=normalized,
    )
