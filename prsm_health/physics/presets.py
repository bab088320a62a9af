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
from prsm_health.physics.geometry import Geometry, Material, require
from prsm_health.physics.parameters import FatigueParameters, FrictionParameters, WearParameters
from prsm_health.yamlio import YamlError, load_yaml_mapping

PRESET_NAMES = (
    "dong2022-downhole",
    "meng2021-fractal",
    "li2020-jamming",
    "meng2022-misalignment",
)


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
        require(self.largest_axial_load_n > 0, "largest_axial_load_n", "must be > 0")
        require(self.largest_radial_load_n >= 0, "largest_radial_load_n", "must be >= 0")
        require(self.largest_speed_rpm > 0, "largest_speed_rpm", "must be > 0")


def _number(data: dict[str, Any], key: str) -> float:
    value = data[key]
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ParameterError(key, f"must be a number, got {value!r}")
    return float(value)


def preset_from_mapping(data: dict[str, Any]) -> Preset:
    """Validate a parsed preset document and build the :class:`Preset`."""
    try:
        geometry_section = dict(data["geometry"])
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
            largest_axial_load_n=_number(data, "largest_axial_load_n"),
            largest_radial_load_n=_number(data, "largest_radial_load_n"),
            largest_speed_rpm=_number(data, "largest_speed_rpm"),
        )
    except KeyError as exc:
        raise ParameterError(str(exc.args[0]), "missing from the preset") from exc


def load_preset_file(path: Path) -> Preset:
    """Load a preset from a YAML file of the bundled format."""
    try:
        return preset_from_mapping(load_yaml_mapping(path))
    except YamlError as exc:
        raise ParameterError("preset", str(exc)) from exc


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
