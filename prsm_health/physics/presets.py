"""Presets: the four papers' PRSMs, shipped as YAML data files that cite their source.

``load_preset("meng2022-misalignment")`` returns a validated :class:`Preset`. A preset file
may also be given by path, so users can describe their own actuator in the same format.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from importlib import resources
from pathlib import Path
from typing import Any

from prsm_health.config import build_dataclass
from prsm_health.physics.errors import ParameterError
from prsm_health.physics.geometry import Geometry, Material, require, require_real
from prsm_health.physics.parameters import FatigueParameters, FrictionParameters, WearParameters
from prsm_health.yamlio import YamlError, load_yaml_mapping

PRESET_NAMES = (
    "dong2022-downhole",
    "meng2021-fractal",
    "li2020-jamming",
    "meng2022-misalignment",
)


#: Smallest ``largest_axial_load_n`` accepted. A PRSM's operating range reaches kN to hundreds
#: of kN; the load tables and the filter's scales are fractions of this load, and at 1e-300 N
#: they underflow (a ZeroDivisionError mid-replay). 1 N is far below any real actuator.
MIN_AXIAL_LOAD_N = 1.0


@dataclass(frozen=True, kw_only=True)
class Preset:
    """A PRSM with all model parameters and the operating range its paper covers."""

    name: str
    source: str
    geometry: Geometry
    friction: FrictionParameters
    wear: WearParameters
    fatigue: FatigueParameters
    largest_axial_load_n: float
    largest_radial_load_n: float
    largest_speed_rpm: float

    def __post_init__(self) -> None:
        for name in ("largest_axial_load_n", "largest_radial_load_n", "largest_speed_rpm"):
            object.__setattr__(self, name, require_real(getattr(self, name), name))
        require(
            self.largest_axial_load_n >= MIN_AXIAL_LOAD_N,
            "largest_axial_load_n",
            f"must be at least {MIN_AXIAL_LOAD_N:g} N (the load tables and the filter's scales "
            f"are fractions of it), got {self.largest_axial_load_n!r}",
        )
        require(
            self.largest_radial_load_n >= 0.0,
            "largest_radial_load_n",
            f"must be >= 0 N, got {self.largest_radial_load_n!r}",
        )
        require(
            self.largest_speed_rpm > 0.0,
            "largest_speed_rpm",
            f"must be > 0 rpm, got {self.largest_speed_rpm!r}",
        )


def preset_from_mapping(data: dict[str, Any]) -> Preset:
    """Validate a parsed preset document and build the :class:`Preset`."""
    try:
        geometry_section = data["geometry"]
        if not isinstance(geometry_section, dict):
            kind = type(geometry_section).__name__
            raise ParameterError("geometry", f"must be a mapping, got {kind}")
        geometry_section = dict(geometry_section)
        materials = {
            part: build_dataclass(Material, geometry_section.pop(part, {}), f"geometry.{part}")
            for part in ("screw", "roller", "nut")
        }
        return Preset(
            name=str(data["name"]),
            source=str(data["source"]),
            geometry=build_dataclass(Geometry, geometry_section, "geometry", **materials),
            friction=build_dataclass(FrictionParameters, data.get("friction"), "friction"),
            wear=build_dataclass(WearParameters, data.get("wear"), "wear"),
            fatigue=build_dataclass(FatigueParameters, data.get("fatigue"), "fatigue"),
            largest_axial_load_n=data["largest_axial_load_n"],
            largest_radial_load_n=data["largest_radial_load_n"],
            largest_speed_rpm=data["largest_speed_rpm"],
        )
    except KeyError as exc:
        raise ParameterError(str(exc.args[0]), "missing from the preset") from exc


def load_preset_file(path: Path) -> Preset:
    """Load a preset from a YAML file of the bundled format."""
    try:
        return preset_from_mapping(load_yaml_mapping(path))
    except YamlError as exc:
        raise ParameterError("preset", str(exc)) from exc
    except ParameterError as exc:  # a bad value: say which file holds it
        raise exc.in_file(path) from exc


@cache
def load_preset(name_or_path: str) -> Preset:
    """Load a bundled preset by name, or a preset file by path."""
    if name_or_path in PRESET_NAMES:
        resource = resources.files("prsm_health.physics") / "presets" / f"{name_or_path}.yaml"
        with resources.as_file(resource) as path:
            return load_preset_file(path)
    path = Path(name_or_path)
    if path.suffix in (".yaml", ".yml"):
        if not path.is_file():
            raise ParameterError("preset", f"no such preset file {name_or_path!r}")
        return load_preset_file(path)
    raise ParameterError(
        "preset",
        f"unknown preset {name_or_path!r}: a preset file ends in .yaml or .yml, or choose one "
        f"of {', '.join(PRESET_NAMES)}",
    )
