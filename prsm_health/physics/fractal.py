"""Fractal (Majumdar-Bhushan) real contact area of one rough contact ellipse (paper 001).

Paper 001 (Meng et al., Fractal Fract. 2021) eq. 3-27: the thread flank profile is an MB fractal
with dimension D and roughness G, both fitted to the roughness Ra (eq. 4-5). Asperities of
contact area a deform plastically when small and elastically when large; the four regimes are
bounded by the critical areas a_pc < a_epc < a_ec (eq. 9-11) and carry the forces of eq. 12.
Their sizes follow the distribution n(a) of eq. 13 up to the largest spot a_L, with the domain
extension factor psi of eq. 14. Integrating force and area over the distribution (eq. 15-22)
gives the contact force F(a_L) and the real contact area A_r(a_L) of one ellipse; solving
F(a_L) = Q gives A_r for a normal contact force Q.

Assumptions (the paper leaves these open):

* Eq. 4 gives G in millimetres when Ra is in micrometres (that reproduces 001 Table 2: Ra 0.3
  -> D 1.607, G 2.93e-9 m; Ra 0.5 -> 1.573, 3.84e-9 m). Table 2's G for Ra 0.8 (5.43e-9 m)
  does not follow from eq. 4 (4.90e-9 m).
* One area variable a throughout: the asperity area of eq. 12 is the one distributed by
  eq. 13, and A_r = integral of a n(a) da (eq. 21 as printed, i.e. the truncated area A'_r;
  we do not halve it). In the fully plastic limit this gives A_r = Q / H exactly.
* The critical elastic area follows from eq. 8-10 evaluated at a = a_ec:
  a_ec = G^2 (pi / (1.4 K phi)^2)^(1 / (D - 1)).
* Screw-roller pair: E_0 from both Young's moduli and Poisson ratios (eq. 9); the hardness
  coefficient K = 0.454 + 0.41 nu uses the mean Poisson ratio; H and the yield strength
  sigma_s (phi = sigma_s / E_0) are those of the softer body.
* The regime forces of eq. 12 are not continuous at the critical areas (e.g. the second
  elastoplastic force is about 0.26 H a at a_pc); F(a_L) is still continuous and strictly
  increasing, so the root F(a_L) = Q is unique.
* The real area is not bounded by the nominal Hertz ellipse area (the MB model does not know
  it); with the paper's G it exceeds pi a b at typical PRSM loads (A_r / A_n about 1.0-1.6 at
  the meng2021-fractal preset, 30 kN). We keep the paper's model and report this.
* Known deviation: with eq. 4-5 the real area at a fixed load falls as Ra rises (346 N:
  2.19e-7 m^2 at Ra 0.3, 1.59e-7 m^2 at Ra 0.8), the opposite of 001 Fig. 11-12 (not
  tuned; the printed model does not give 001's trend).

Vectorised evaluation uses a monotone table log Q -> log A_r per surface (cached), exact on the
fully plastic branch (A_r = Q / H below F(a_pc)); its relative error against the direct root
solve is below 5e-6 (2.3e-6 measured on the meng2021-fractal surface; checked in the tests).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import brentq

from prsm_health.physics.errors import ConvergenceError, DomainError, ParameterError
from prsm_health.physics.geometry import Material

FloatArray = NDArray[np.float64]

#: Largest normal force of one contact ellipse the area table covers [N].
LARGEST_TABLE_LOAD_N = 1.0e6
_TABLE_POINTS = 1200


def fractal_dimension(ra_m: float) -> float:
    """D = 1.528 / Ra^0.042 with Ra in micrometres (paper 001 eq. 5)."""
    return float(1.528 / _ra_um(ra_m) ** 0.042)


def fractal_roughness_m(ra_m: float) -> float:
    """G = 10^-(5.26 / Ra^0.042) [mm], Ra in micrometres (paper 001 eq. 4), returned in m."""
    return float(1e-3 * 10.0 ** (-5.26 / _ra_um(ra_m) ** 0.042))


def _ra_um(ra_m: float) -> float:
    if not (math.isfinite(ra_m) and ra_m > 0.0):
        raise ParameterError("wear.surface_roughness_ra_m", f"must be finite and > 0, got {ra_m!r}")
    return ra_m * 1e6


def domain_extension_factor(dimension: float) -> float:
    """psi > 1 solving (psi^((2-D)/2) - (1 + psi^(-D/2))^((D-2)/D)) / ((2-D)/D) = 1 (001 eq. 14)."""
    if not 1.0 < dimension < 2.0:
        raise ParameterError("fractal_dimension", f"must be in (1, 2), got {dimension!r}")
    d = dimension

    def residual(psi: float) -> float:
        return float(
            (psi ** ((2.0 - d) / 2.0) - (1.0 + psi ** (-d / 2.0)) ** ((d - 2.0) / d))
            / ((2.0 - d) / d)
            - 1.0
        )

    # The residual is negative at psi = 1 and grows without bound; widen until bracketed.
    upper = 2.0
    while residual(upper) < 0.0:
        upper *= 2.0
    return float(brentq(residual, 1.0, upper, xtol=1e-14, rtol=1e-14))


def _power_integral(lower: float, upper: FloatArray, exponent: float) -> FloatArray:
    """Integral of a^exponent from ``lower`` to ``upper`` (>= lower), exact at exponent -1."""
    power = exponent + 1.0
    if lower == 0.0:
        return np.asarray(upper**power / power, dtype=np.float64)
    log_ratio = np.log(upper / lower)
    if power == 0.0:
        return np.asarray(log_ratio, dtype=np.float64)
    return np.asarray(lower**power * np.expm1(power * log_ratio) / power, dtype=np.float64)


@dataclass(frozen=True)
class FractalSurface:
    """Load-independent constants of the rough screw-roller contact (paper 001 eq. 4-14).

    dimension, roughness_m: D and G (eq. 4-5); psi: domain extension factor (eq. 14);
    equivalent_modulus_pa: E_0 (eq. 9); hardness_pa: H; hardness_coefficient: K (eq. 9);
    yield_ratio: phi = sigma_s / E_0; critical areas a_ec, a_epc, a_pc in m^2 (eq. 10-11).
    """

    dimension: float
    roughness_m: float
    psi: float
    equivalent_modulus_pa: float
    hardness_pa: float
    hardness_coefficient: float
    yield_ratio: float
    elastic_area_m2: float
    elastoplastic_area_m2: float
    plastic_area_m2: float

    def _density_factor(self, largest_spot_m2: FloatArray) -> FloatArray:
        """(D/2) psi^((2-D)/2) a_L^(D/2): n(a) = this * a^(-(D+2)/2) (001 eq. 13)."""
        d = self.dimension
        return np.asarray(
            d / 2.0 * self.psi ** ((2.0 - d) / 2.0) * largest_spot_m2 ** (d / 2.0),
            dtype=np.float64,
        )

    def load_n(self, largest_spot_m2: ArrayLike) -> FloatArray:
        """Total force F(a_L) on one ellipse, summed over the four regimes (001 eq. 12-22)."""
        a_l = np.asarray(largest_spot_m2, dtype=np.float64)
        d, h, k = self.dimension, self.hardness_pa, self.hardness_coefficient
        a_pc, a_epc, a_ec = self.plastic_area_m2, self.elastoplastic_area_m2, self.elastic_area_m2
        tail = -(d + 2.0) / 2.0  # exponent of the size distribution n(a)
        plastic = h * _power_integral(0.0, np.minimum(a_l, a_pc), 1.0 + tail)
        second = (
            0.9992
            * k
            * h
            * a_ec**-0.1021
            * _power_integral(a_pc, np.clip(a_l, a_pc, a_epc), 1.1021 + tail)
        )
        first = (
            0.7521
            * k
            * h
            * a_ec**-0.2544
            * _power_integral(a_epc, np.clip(a_l, a_epc, a_ec), 1.2544 + tail)
        )
        elastic = (
            4.0
            * math.sqrt(math.pi)
            / 3.0
            * self.equivalent_modulus_pa
            * self.roughness_m ** (d - 1.0)
            * _power_integral(a_ec, np.maximum(a_l, a_ec), (3.0 - d) / 2.0 + tail)
        )
        total = self._density_factor(a_l) * (plastic + second + first + elastic)
        return np.asarray(total, dtype=np.float64)

    def real_area_m2(self, largest_spot_m2: ArrayLike) -> FloatArray:
        """A_r = integral of a n(a) da = D / (2 - D) psi^((2-D)/2) a_L (001 eq. 15, 21)."""
        d = self.dimension
        return np.asarray(
            d
            / (2.0 - d)
            * self.psi ** ((2.0 - d) / 2.0)
            * np.asarray(largest_spot_m2, dtype=np.float64),
            dtype=np.float64,
        )


@cache
def fractal_surface(screw: Material, roller: Material, ra_m: float) -> FractalSurface:
    """Constants of the rough screw-roller contact for a roughness Ra (001 eq. 4-5, 9-11, 14)."""
    d = fractal_dimension(ra_m)
    g = fractal_roughness_m(ra_m)
    if not 1.0 < d < 2.0:
        raise ParameterError(
            "wear.surface_roughness_ra_m", f"Ra = {ra_m!r} m gives D = {d:.4f} outside (1, 2)"
        )
    modulus = 1.0 / (screw.compliance_per_pa + roller.compliance_per_pa)
    k = 0.454 + 0.41 * (screw.poisson_ratio + roller.poisson_ratio) / 2.0
    phi = min(screw.yield_strength_pa, roller.yield_strength_pa) / modulus
    a_ec = g**2 * (math.pi / (1.4 * k * phi) ** 2) ** (1.0 / (d - 1.0))
    return FractalSurface(
        dimension=d,
        roughness_m=g,
        psi=domain_extension_factor(d),
        equivalent_modulus_pa=modulus,
        hardness_pa=min(screw.hardness_pa, roller.hardness_pa),
        hardness_coefficient=k,
        yield_ratio=phi,
        elastic_area_m2=a_ec,
        elastoplastic_area_m2=6.0 ** (1.0 / (1.0 - d)) * a_ec,
        plastic_area_m2=110.0 ** (1.0 / (1.0 - d)) * a_ec,
    )


def solve_largest_spot_m2(surface: FractalSurface, load_n: float) -> float:
    """Largest spot a_L with F(a_L) = Q by a bracketed root solve, residual checked (001 eq. 22).

    Reference solver for one load; :func:`real_contact_area_m2` is the fast vectorised path.
    """
    if not (math.isfinite(load_n) and load_n >= 0.0):
        raise ParameterError("load_n", f"must be finite and >= 0, got {load_n!r}")
    lower = surface.plastic_area_m2
    if load_n <= float(surface.load_n(lower)):  # fully plastic: F = H A_r exactly
        return load_n / surface.hardness_pa * lower / float(surface.real_area_m2(lower))
    upper = 10.0 * lower
    while float(surface.load_n(upper)) < load_n:
        upper *= 10.0
    # F is continuous and strictly increasing; solve in log a_L for scale freedom.
    root = math.exp(
        brentq(
            lambda log_a: float(surface.load_n(math.exp(log_a))) / load_n - 1.0,
            math.log(lower),
            math.log(upper),
            xtol=1e-13,
            rtol=1e-14,
        )
    )
    residual = abs(float(surface.load_n(root)) / load_n - 1.0)
    if residual > 1e-9:
        raise ConvergenceError(f"fractal load balance residual {residual:.3g} > 1e-9")
    return root


@dataclass(frozen=True)
class _AreaTable:
    log_load: FloatArray
    log_area: FloatArray
    plastic_limit_n: float


@cache
def _area_table(surface: FractalSurface) -> _AreaTable:
    """Monotone table log F -> log A_r from a_pc up to LARGEST_TABLE_LOAD_N (001 eq. 15-22)."""
    lower = surface.plastic_area_m2
    # A hair beyond the documented limit, so that the table (which ends at the load of a root
    # solved to a tolerance) covers LARGEST_TABLE_LOAD_N itself.
    upper = solve_largest_spot_m2(surface, 1.001 * LARGEST_TABLE_LOAD_N)
    spots = np.unique(
        np.concatenate(
            [
                np.geomspace(lower, upper, _TABLE_POINTS),
                [surface.elastoplastic_area_m2, surface.elastic_area_m2],
            ]
        )
    )
    loads = surface.load_n(spots)
    return _AreaTable(
        log_load=np.log(loads),
        log_area=np.log(surface.real_area_m2(spots)),
        plastic_limit_n=float(loads[0]),
    )


def real_contact_area_m2(surface: FractalSurface, load_n: ArrayLike) -> FloatArray:
    """Real contact area A_r of ellipses carrying normal forces Q, any shape (001 eq. 12-22,
    integrated exactly rather than through eq. 23-24's dimensionless closed form).

    Fully plastic loads (a_L <= a_pc) give A_r = Q / H exactly; above, log-log interpolation in
    the cached monotone table. Q must be finite, >= 0 and at most LARGEST_TABLE_LOAD_N.
    """
    load = np.asarray(load_n, dtype=np.float64)
    table = _area_table(surface)
    if not np.all(np.isfinite(load)) or np.any(load < 0.0):
        raise ParameterError("load_n", "contact forces must be finite and >= 0")
    if np.any(load > LARGEST_TABLE_LOAD_N):
        raise DomainError(
            f"contact force {float(load.max()):.4g} N exceeds the fractal table's "
            f"{LARGEST_TABLE_LOAD_N:.4g} N"
        )
    plastic = load <= table.plastic_limit_n
    log_load = np.log(np.where(plastic, table.plastic_limit_n, load))
    interpolated = np.exp(np.interp(log_load, table.log_load, table.log_area))
    return np.asarray(np.where(plastic, load / surface.hardness_pa, interpolated), dtype=np.float64)
