"""The physics the filter needs, averaged over the carrier angle, and its cached tables.

Inside the filter the PRSM is described per roller and averaged over the roller's position
angle, because which roller jams and the carrier phase are unknown; the angle-dependent part
of a jammed roller's torque is the carrier-harmonic ripple, which the filter estimates as
states of its own (docs/estimation.md). With k of N rollers jammed (paper 002 eq. 12-18, per
roller):

    M_k(F, w)    = (N - k) (rolling(F) + viscous(F) |w|^0.66) + k sliding(F)
    dh/dt_k(F, w) = |w| ((N - k) wear_healthy(F) + k wear_jammed(F))
    dD/dt(F, w)  = |w| damage(F)

with F the axial load magnitude and w the screw speed. ``rolling`` is hysteresis + spin +
differential sliding (002 eq. 2-4), ``viscous`` the lubricant term at 1 rad/s (eq. 5-11,
the only speed-dependent one, exponent 0.66 of eq. 5), ``sliding`` a jammed roller's Coulomb
sliding (eq. 15-16), the wear rates per radian of screw rotation (001 eq. 30-38 / 004
eq. 32-35 with the healthy and the jammed slip speed), and ``damage`` the Miner damage per
radian (000 eq. 29). The load distribution does not depend on which rollers are jammed.

:func:`physics_averages` computes these from the physics core (the reference, and the
"full physics" of the naive configuration); :class:`AveragedTables` tabulates them once per
(preset, misalignment, radial ratio, case) over the load, interpolated in log-log (every term
is close to a power law of the load), with the error against the physics core measured in
the tests.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from functools import cache
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from prsm_health.physics.fatigue import damage_rate_from_peak_per_s
from prsm_health.physics.geometry import Misalignment
from prsm_health.physics.load_distribution import NEGLIGIBLE_LOAD_N, LoadingCase
from prsm_health.physics.presets import Preset
from prsm_health.physics.roller_table import roller_values

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class RollerAverages:
    """Per-roller physics averaged over the carrier angle, one entry per axial load.

    rolling_nm: hysteresis + spin + differential torque of one healthy roller [N m].
    viscous_nm: viscous torque of one healthy roller at |w_s| = 1 rad/s [N m].
    sliding_nm: sliding torque of one jammed roller [N m].
    wear_healthy_m, wear_jammed_m: precision loss per radian of screw rotation contributed by
    one roller, healthy or jammed [m/rad]. damage: Miner damage of the PRSM per radian [1/rad].
    """

    rolling_nm: FloatArray
    viscous_nm: FloatArray
    sliding_nm: FloatArray
    wear_healthy_m: FloatArray
    wear_jammed_m: FloatArray
    damage: FloatArray


def physics_averages(
    preset: Preset,
    axial_load_n: ArrayLike,
    *,
    radial_ratio: float = 0.0,
    case: LoadingCase = LoadingCase.SCREW_TENSION_NUT_COMPRESSION,
    misalignment: Misalignment | None = None,
    angles: int = 4,
) -> RollerAverages:
    """:class:`RollerAverages` from the physics core for each axial load (1-D array).

    The average of :func:`~prsm_health.physics.roller_table.roller_values` over the N rollers
    at ``angles`` carrier angles in [0, 2 pi / N), i.e. over N * angles evenly spaced roller
    position angles (exact for harmonics below that number).
    """
    geometry = preset.geometry
    loads = np.atleast_1d(np.asarray(axial_load_n, dtype=np.float64))[:, None]
    theta = 2.0 * math.pi * np.arange(angles) / (angles * geometry.n_rollers)
    rollers = roller_values(
        preset,
        loads,
        radial_load_n=radial_ratio * loads,
        carrier_angle_rad=theta[None, :],
        misalignment=misalignment,
        case=case,
    )  # (loads, angles, N)
    peak = rollers.peak_contact_force_n.max(axis=-1)
    damage = damage_rate_from_peak_per_s(geometry, preset.fatigue, peak, 1.0)

    def mean(per_roller: FloatArray) -> FloatArray:
        return np.asarray(per_roller.mean(axis=(1, 2)), dtype=np.float64)

    return RollerAverages(
        rolling_nm=mean(rollers.rolling_torque_nm),
        viscous_nm=mean(rollers.viscous_torque_nm),
        sliding_nm=mean(rollers.jammed_torque_nm),
        wear_healthy_m=mean(rollers.wear_m_per_rad),
        wear_jammed_m=mean(rollers.jammed_wear_m_per_rad),
        damage=np.asarray(damage.mean(axis=1), dtype=np.float64),
    )


#: Carrier angles over a turn at which :func:`jammed_ripple_nm_per_n` resolves the ripple.
RIPPLE_ANGLES = 36
#: Radial load of that computation, as a fraction of the preset's largest axial load.
RIPPLE_RADIAL_FRACTION = 0.1


@cache
def jammed_ripple_nm_per_n(preset: Preset) -> float:
    """The carrier-frequency ripple of one jammed roller per newton of radial load [N m/N]:
    the first carrier harmonic's amplitude of its sliding torque (002 eq. 15-16) on the
    contact loads of the radially loaded screw (000 eq. 7-25), over RIPPLE_ANGLES carrier
    angles at the preset's largest axial load and RIPPLE_RADIAL_FRACTION of it radial.

    The physics core makes it proportional to the radial load whatever the axial load, the
    same in both loading cases (0.530 N m per kN on dong2022-downhole, 0.371 on
    meng2022-misalignment; up to a radial load of a quarter of the axial, 0.5 % more at two
    thirds on li2020-jamming); a misalignment alone makes none, and with a radial load moves it
    by up to 2 % at 2' of tilt, 13 % at 5' and small axial loads (docs/estimation.md, "The
    ripple's size, from the physics").
    """
    theta = np.linspace(0.0, 2.0 * math.pi, RIPPLE_ANGLES, endpoint=False)
    axial_n = preset.largest_axial_load_n
    radial_n = RIPPLE_RADIAL_FRACTION * axial_n
    torque = roller_values(
        preset, axial_n, radial_load_n=radial_n, carrier_angle_rad=theta
    ).jammed_torque_nm[:, 0]
    harmonic = 2.0 * abs(complex(np.mean(torque * np.exp(-1j * theta))))
    return harmonic / radial_n


#: Order of the quantities in the value vectors of :class:`AverageModel`.
QUANTITIES = tuple(f.name for f in fields(RollerAverages))
ROLLING, VISCOUS, SLIDING, WEAR_HEALTHY, WEAR_JAMMED, DAMAGE = range(len(QUANTITIES))

#: Table grid: loads from this fraction of the preset's largest load ...
TABLE_MIN_FRACTION = 1e-3
#: ... to this multiple of it, log-spaced.
TABLE_MAX_FRACTION = 3.0
TABLE_POINTS = 48
#: Relative step of the finite-difference derivative of the direct physics.
_DIFFERENCE_STEP = 1e-4


class AverageModel(Protocol):
    """The averaged physics at one load: values and d/dF, ordered as :data:`QUANTITIES`."""

    def evaluate(self, axial_load_n: float) -> tuple[FloatArray, FloatArray]:
        """Values and their derivatives with respect to the load magnitude |F|."""


@dataclass(frozen=True, eq=False)
class AveragedTables:
    """:class:`RollerAverages` tabulated over the load for one configuration (the surrogate).

    Each quantity is stored as its log (floored at 1e-300 so an unloaded term stays finite)
    on a log-spaced load grid; :meth:`evaluate` interpolates linearly in log-log, extends the
    end intervals as power laws outside the grid, and is exactly zero at F = 0.
    """

    log_load: FloatArray
    log_values: FloatArray  # (quantities, loads)
    slopes: FloatArray  # d log(value) / d log(load) per interval, (quantities, loads - 1)

    def evaluate(self, axial_load_n: float) -> tuple[FloatArray, FloatArray]:
        """Values and d/dF at the load magnitude |F| (scalar)."""
        load = abs(axial_load_n)
        if load < NEGLIGIBLE_LOAD_N:
            zeros = np.zeros(len(QUANTITIES))
            return zeros, zeros
        x = math.log(load)
        grid = self.log_load
        index = min(max(int(grid.searchsorted(x)) - 1, 0), len(grid) - 2)
        slope = self.slopes[:, index]
        value = np.exp(self.log_values[:, index] + slope * (x - grid[index]))
        return value, value * slope / load


@cache
def averaged_tables(
    preset: Preset,
    misalignment: Misalignment,
    radial_ratio: float,
    case: LoadingCase,
) -> AveragedTables:
    """Build (once per configuration) the load table of :func:`physics_averages`."""
    largest = preset.largest_axial_load_n
    loads = np.geomspace(TABLE_MIN_FRACTION * largest, TABLE_MAX_FRACTION * largest, TABLE_POINTS)
    averages = physics_averages(
        preset, loads, radial_ratio=radial_ratio, case=case, misalignment=misalignment
    )
    values = np.stack([getattr(averages, name) for name in QUANTITIES])
    log_values = np.log(np.maximum(values, 1e-300))
    log_load = np.log(loads)
    slopes = np.diff(log_values, axis=1) / np.diff(log_load)
    return AveragedTables(log_load=log_load, log_values=log_values, slopes=slopes)


@dataclass(frozen=True, eq=False)
class DirectPhysics:
    """The physics core itself at every evaluation (the naive reference configuration).

    One carrier angle per evaluation (the N rollers sample N position angles), the
    derivative by a forward difference: two load-distribution solves per call.
    """

    preset: Preset
    misalignment: Misalignment
    radial_ratio: float
    case: LoadingCase

    def evaluate(self, axial_load_n: float) -> tuple[FloatArray, FloatArray]:
        """Values and d/dF at the load magnitude |F| (scalar), from the physics core; beyond
        the surrogate's largest load (TABLE_MAX_FRACTION of the preset's largest) extended as
        a power law with the slope there, as the tables extend theirs (the physics core
        refuses contact forces beyond its fractal table: a load a filter tried far out, a UKF
        sigma point, raised a DomainError; found by a review session)."""
        load = abs(axial_load_n)
        edge = TABLE_MAX_FRACTION * self.preset.largest_axial_load_n
        if load <= edge:
            return self._physics(load)
        at_edge, slope_at_edge = self._physics(edge)
        log_slope = np.divide(
            slope_at_edge * edge, at_edge, out=np.zeros_like(at_edge), where=at_edge > 0.0
        )
        value = at_edge * (load / edge) ** log_slope
        return value, value * log_slope / load

    def _physics(self, load: float) -> tuple[FloatArray, FloatArray]:
        """Values and d/dF at ``load`` >= 0 from the physics core (forward difference)."""
        step = max(load, NEGLIGIBLE_LOAD_N) * _DIFFERENCE_STEP
        averages = physics_averages(
            self.preset,
            [load, load + step],
            radial_ratio=self.radial_ratio,
            case=self.case,
            misalignment=self.misalignment,
            angles=1,
        )
        values = np.stack([getattr(averages, name) for name in QUANTITIES])
        return values[:, 0], (values[:, 1] - values[:, 0]) / step
