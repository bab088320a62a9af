"""PRSM geometry and materials as validated, frozen dataclasses (SI units throughout).

Symbols follow the papers: screw (s), roller (r), nut (n); flank (contact) angle beta, helix
angles lambda. Derived quantities are properties, so a geometry cannot hold inconsistent copies.
The geometric conventions that the papers leave open are written down in docs/physics.md.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields

from prsm_health.physics.errors import ParameterError


def require(ok: bool, name: str, message: str) -> None:
    """Raise :class:`ParameterError` naming ``name`` unless ``ok``."""
    if not ok:
        raise ParameterError(name, message)


def _shown(value: object) -> str:
    """``repr(value)`` for an error message, except an integer too long for one line."""
    if isinstance(value, int) and abs(value) >= 10**20:  # repr fails beyond 4300 digits
        return f"an integer of about {int(value.bit_length() * math.log10(2)) + 1} digits"
    return repr(value)


def require_real(value: object, name: str) -> float:
    """``value`` as a float, refused by ``name`` unless it is a finite int or float.

    The one check of every real-valued parameter, whatever its range: refuses a string or
    null from a data file, a bool (YAML's ``true`` is no number, though Python counts it as
    1), NaN and infinities, and an integer too large for a float (YAML reads 400 digits as an
    int, which float() refuses with an OverflowError).
    """
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ParameterError(name, f"must be a number, got {_shown(value)}")
    try:
        number = float(value)
    except OverflowError:
        number = math.inf
    require(math.isfinite(number), name, f"must be a finite number, got {_shown(value)}")
    return number


def require_integer(value: object, name: str, low: int, high: int | None = None) -> int:
    """``value``, refused by ``name`` unless it is an int in [low, high] (no upper bound when
    ``high`` is None).

    The one check of every integer parameter. A bool is refused although Python counts it as
    an int: YAML's ``true`` is no count, and numpy takes a bool where an index was meant as a
    mask (a jam count of True would select every hypothesis).
    """
    if (
        isinstance(value, bool)
        or not isinstance(value, int)
        or value < low
        or (high is not None and value > high)
    ):
        in_range = f"in [{low}, {high}]" if high is not None else f">= {low}"
        raise ParameterError(name, f"must be an integer {in_range}, got {_shown(value)}")
    return value


def require_ranges(
    obj: object, prefix: str, ranges: Mapping[str, tuple[float, float] | None]
) -> None:
    """Each named field of the frozen dataclass ``obj`` must be a finite number
    (:func:`require_real`) inside its closed range ``(low, high)``, or > 0 where the range is
    None; it is stored as a float. Every field that is not is named at once, so that one edit
    of a data file fixes them all."""
    problems: list[ParameterError] = []
    for key, bounds in ranges.items():
        name = f"{prefix}.{key}"
        try:
            value = require_real(getattr(obj, key), name)
            if bounds is None:
                require(value > 0.0, name, f"must be > 0, got {value!r}")
            else:
                low, high = bounds
                require(
                    low <= value <= high, name, f"must be in [{low:g}, {high:g}], got {value!r}"
                )
        except ParameterError as exc:
            problems.append(exc)
            continue
        object.__setattr__(obj, key, value)
    if problems:
        raise ParameterError.combined(problems)


def require_finite_positive(obj: object, prefix: str) -> None:
    """Every ``float`` field of the frozen dataclass ``obj`` must be a finite number > 0
    (:func:`require_ranges`).

    Integers are accepted and stored as floats; anything else (a string from a data file, a
    bool) is refused with the field's name (:func:`require_real`).
    """
    floats = [f.name for f in fields(obj) if f.type in (float, "float")]  # type: ignore[arg-type]
    require_ranges(obj, prefix, dict.fromkeys(floats))


@dataclass(frozen=True, kw_only=True)
class Material:
    """Linear-elastic material with the hardness used by wear and fractal contact.

    Defaults are GCr15 bearing steel: E = 212 GPa (004 Table 1), nu = 0.29 (001 and 004
    Table 1), HRC 60 (about 697 HV, so H = 6.84 GPa; our choice within 004's 56-62, 001 gives
    62), yield strength 1.7 GPa (paper 002, section 3.2).
    """

    youngs_modulus_pa: float = 2.12e11
    poisson_ratio: float = 0.29
    hardness_pa: float = 6.84e9
    yield_strength_pa: float = 1.7e9

    def __post_init__(self) -> None:
        require_finite_positive(self, "material")
        require(self.poisson_ratio < 0.5, "material.poisson_ratio", "must be < 0.5")

    @property
    def compliance_per_pa(self) -> float:
        """(1 - nu^2) / E, this body's share of the Hertz contact compliance (001 eq. 9, 004
        eq. 20)."""
        return (1.0 - self.poisson_ratio**2) / self.youngs_modulus_pa

    @property
    def shear_modulus_pa(self) -> float:
        """G = E / (2 (1 + nu)), the shear modulus of the torsion error (000 eq. 2)."""
        return self.youngs_modulus_pa / (2.0 * (1.0 + self.poisson_ratio))


#: Upper bounds of the geometry's counts: far beyond any PRSM built (5 to 14 rollers, a few
#: starts, tens of threads) yet small enough that the model's (n_rollers, n_threads) arrays
#: and the lead (starts times pitch) stay computable; a count of 10**400 would otherwise fail
#: deep in the physics with an OverflowError or an array too large to allocate.
_COUNT_LIMITS = {"screw_starts": 100, "nut_starts": 100, "n_rollers": 100, "n_threads": 1000}


@dataclass(frozen=True, kw_only=True)
class Geometry:
    """Nominal geometry of a standard PRSM (screw, N rollers, nut; rollers single-start).

    Radii are nominal (pitch) radii. ``thread_half_thickness_*_m`` are half tooth thicknesses
    at the nominal radius (paper 004 Table 2 "c"); they only set the unloaded axial clearance.
    """

    screw_radius_m: float
    roller_radius_m: float
    nut_radius_m: float
    nut_outer_radius_m: float
    pitch_m: float
    screw_starts: int
    nut_starts: int
    flank_angle_rad: float
    n_rollers: int
    n_threads: int
    thread_half_thickness_screw_m: float
    thread_half_thickness_roller_m: float
    thread_half_thickness_nut_m: float
    screw_root_radius_m: float
    screw_crest_radius_m: float
    roller_root_radius_m: float
    roller_crest_radius_m: float
    screw: Material = field(default_factory=Material)
    roller: Material = field(default_factory=Material)
    nut: Material = field(default_factory=Material)

    def __post_init__(self) -> None:
        require_finite_positive(self, "geometry")
        for name, high in _COUNT_LIMITS.items():
            require_integer(getattr(self, name), f"geometry.{name}", 1, high)
        require(
            self.flank_angle_rad < math.pi / 2,
            "geometry.flank_angle_rad",
            f"must be in (0, pi/2), got {self.flank_angle_rad!r}",
        )
        require(
            self.roller_radius_m < self.screw_radius_m,
            "geometry.roller_radius_m",
            f"roller ({self.roller_radius_m} m) must be smaller than the screw "
            f"({self.screw_radius_m} m)",
        )
        require(
            self.nut_radius_m > self.screw_radius_m + self.roller_radius_m,
            "geometry.nut_radius_m",
            "must exceed screw_radius_m + roller_radius_m (rollers sit between screw and nut)",
        )
        require(
            self.nut_outer_radius_m > self.nut_radius_m,
            "geometry.nut_outer_radius_m",
            "must exceed nut_radius_m",
        )
        require(
            self.n_rollers == 1
            or math.sin(math.pi / self.n_rollers) * self.carrier_radius_m > self.roller_radius_m,
            "geometry.n_rollers",
            f"{self.n_rollers} rollers of radius {self.roller_radius_m} m overlap on the carrier "
            f"circle of radius {self.carrier_radius_m} m",
        )
        require(
            self.screw_root_radius_m < self.screw_radius_m < self.screw_crest_radius_m,
            "geometry.screw_radius_m",
            "must lie between screw_root_radius_m and screw_crest_radius_m",
        )
        require(
            self.roller_root_radius_m < self.roller_radius_m < self.roller_crest_radius_m,
            "geometry.roller_radius_m",
            "must lie between roller_root_radius_m and roller_crest_radius_m",
        )
        require(
            self.thread_half_thickness_screw_m + self.thread_half_thickness_roller_m
            < self.pitch_m / 2,
            "geometry.thread_half_thickness_screw_m",
            "screw and roller teeth (2c_s + 2c_r) must fit in one pitch",
        )

    # --- derived quantities -------------------------------------------------------------
    @property
    def carrier_radius_m(self) -> float:
        """Distance from the screw axis to a roller axis, r_s + r_r (004 eq. 24, 30)."""
        return self.screw_radius_m + self.roller_radius_m

    @property
    def lead_m(self) -> float:
        """Screw lead L = n_s p (paper 002 eq. 19 uses the lead)."""
        return self.screw_starts * self.pitch_m

    @property
    def screw_helix_angle_rad(self) -> float:
        """lambda_s = atan(n_s p / (2 pi r_s)) (paper 004, section 2.2)."""
        return math.atan(self.lead_m / (2.0 * math.pi * self.screw_radius_m))

    @property
    def roller_helix_angle_rad(self) -> float:
        """lambda_r = atan(p / (2 pi r_r)) (paper 004, section 2.2)."""
        return math.atan(self.pitch_m / (2.0 * math.pi * self.roller_radius_m))

    @property
    def effective_ball_radius_m(self) -> float:
        """R = r_r / sin(beta): radius of the roller's arc flank profile (paper 004 eq. 25)."""
        return self.roller_radius_m / math.sin(self.flank_angle_rad)

    @property
    def axial_projection(self) -> float:
        """sin(beta) cos(lambda): axial component of a unit normal contact force (004 eq. 18)."""
        return math.sin(self.flank_angle_rad) * math.cos(self.roller_helix_angle_rad)

    @property
    def radial_projection(self) -> float:
        """cos(beta): radial component of a unit normal contact force (paper 000 eq. 9, 12)."""
        return math.cos(self.flank_angle_rad)

    @property
    def screw_area_m2(self) -> float:
        """Nominal screw cross-section A_s = pi r_s^2 (paper 004 eq. 16)."""
        return math.pi * self.screw_radius_m**2

    @property
    def roller_area_m2(self) -> float:
        """Nominal roller cross-section A_r = pi r_r^2 (paper 004 eq. 16)."""
        return math.pi * self.roller_radius_m**2

    @property
    def nut_area_m2(self) -> float:
        """Nut cross-section A_N = pi (R_N1^2 - R_N2^2) (paper 000, after eq. 17)."""
        return math.pi * (self.nut_outer_radius_m**2 - self.nut_radius_m**2)

    @property
    def roller_angles_rad(self) -> tuple[float, ...]:
        """Nominal position angles tau_i = 2 pi (i - 1) / N of the rollers (paper 004 eq. 4)."""
        return tuple(2.0 * math.pi * i / self.n_rollers for i in range(self.n_rollers))


@dataclass(frozen=True, kw_only=True)
class Misalignment:
    """Screw misalignment of paper 004 Table 3: tilt angles about x and y, and an offset."""

    tilt_x_rad: float = 0.0
    tilt_y_rad: float = 0.0
    offset_x_m: float = 0.0
    offset_y_m: float = 0.0

    def __post_init__(self) -> None:
        limit = math.radians(1.0)
        for f in fields(self):
            value = require_real(getattr(self, f.name), f"misalignment.{f.name}")
            object.__setattr__(self, f.name, value)
        for name in ("tilt_x_rad", "tilt_y_rad"):
            value = getattr(self, name)
            require(
                abs(value) <= limit,
                f"misalignment.{name}",
                f"|{value!r}| rad exceeds the small-angle model limit of 1 degree",
            )

    @property
    def is_aligned(self) -> bool:
        """True when there is neither tilt nor offset (the radial/misalignment terms drop)."""
        return not any(getattr(self, f.name) for f in fields(self))

    @classmethod
    def from_arcmin(cls, tilt_x_arcmin: float, tilt_y_arcmin: float) -> Misalignment:
        """Build from tilt angles in arc minutes (the papers' unit)."""
        return cls(
            tilt_x_rad=math.radians(tilt_x_arcmin / 60.0),
            tilt_y_rad=math.radians(tilt_y_arcmin / 60.0),
        )
