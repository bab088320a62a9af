"""A scene: everything the truth simulator needs to make one run, read from a YAML file.

``load_scene("nominal-downhole")`` reads a bundled scene (``prsm_health/scenes/data``), or a
path to a YAML file of the same format. Unknown keys and bad values are refused with their
dotted name (``profile.speed_rpm``, ``jams[1].roller``, ``sensor_faults.spikes[0].field``).
The format is documented in docs/scenes.md; the sections are built by their own modules.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import yaml

from prsm_health.actuator import Actuator, actuator_from_mapping, preset_beside_file
from prsm_health.physics.errors import ParameterError
from prsm_health.scenes.drive import SpeedLoop
from prsm_health.scenes.faults import SensorFaults, sensor_faults_from_mapping
from prsm_health.scenes.noise import Stream, scene_generator
from prsm_health.scenes.profiles import (
    ConstantRadial,
    DownholeCycle,
    LoadNoise,
    Profile,
    RadialLoad,
    profile_from_mapping,
    radial_load_from_mapping,
)
from prsm_health.scenes.sensors import Sensors
from prsm_health.scenes.validation import flag, integer, items, number, prefixed, section, text
from prsm_health.yamlio import YamlError, load_yaml_mapping

#: The bags of the bundled scenes in a source checkout (``make bags`` writes them).
BUNDLED_BAGS = Path(__file__).resolve().parents[2] / "bags"


@dataclass(frozen=True, kw_only=True)
class Jam:
    """Roller ``roller`` (1-based) jams at ``time_s`` and stays jammed."""

    time_s: float
    roller: int

    def __post_init__(self) -> None:
        number(self, "time_s", low=0.0)
        integer(self, "roller", low=1)


@dataclass(frozen=True, kw_only=True)
class Wear:
    """The scene's wear coefficient relative to the preset's: fixed, or drawn from a prior.

    coefficient_factor: the factor itself. prior_sigma_ln: draw it lognormal with median 1
    and this standard deviation of its logarithm, from the scene seed. At most one is given;
    neither means a factor of 1.
    """

    coefficient_factor: float | None = None
    prior_sigma_ln: float | None = None

    def __post_init__(self) -> None:
        if self.coefficient_factor is not None and self.prior_sigma_ln is not None:
            raise ParameterError("prior_sigma_ln", "give coefficient_factor or prior_sigma_ln")
        if self.coefficient_factor is not None:
            number(self, "coefficient_factor", low=0.0, open_low=True)
        if self.prior_sigma_ln is not None:
            number(self, "prior_sigma_ln", low=0.0)

    def factor(self, seed: int) -> float:
        """The wear-coefficient factor of a run with ``seed``."""
        if self.prior_sigma_ln is not None:
            draw = scene_generator(seed, Stream.WEAR_PRIOR).standard_normal()
            return math.exp(self.prior_sigma_ln * float(draw))
        return self.coefficient_factor if self.coefficient_factor is not None else 1.0


@dataclass(frozen=True, kw_only=True)
class Scene:
    """One simulated run (see docs/scenes.md for every field)."""

    name: str
    description: str = ""
    actuator: Actuator
    duration_s: float
    rate_hz: float = 1000.0
    seed: int = 0
    exact: bool = False
    profile: Profile
    radial_load: RadialLoad = field(default_factory=ConstantRadial)
    load_noise: LoadNoise = field(default_factory=LoadNoise)
    jams: tuple[Jam, ...] = ()
    wear: Wear = field(default_factory=Wear)
    speed_loop: SpeedLoop = field(default_factory=SpeedLoop)
    sensors: Sensors = field(default_factory=Sensors)
    sensor_faults: SensorFaults = field(default_factory=SensorFaults)
    truth_rate_hz: float = 100.0
    joint_states: bool = False
    #: The ``actuator`` section as the scene file wrote it (YAML), recorded into the bags
    #: simulated from the scene (:mod:`prsm_health.scenes.recording`); it must build
    #: ``actuator``. None for a scene built in code: its bags record no actuator.
    actuator_yaml: str | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        if self.actuator_yaml is not None and (
            actuator_from_mapping(yaml.safe_load(self.actuator_yaml)) != self.actuator
        ):
            raise ParameterError("actuator", "does not match the section it was read from")
        if not text(self, "name"):
            raise ParameterError("name", "must not be empty")
        text(self, "description")
        number(self, "duration_s", low=0.0, open_low=True)
        number(self, "rate_hz", low=0.0, open_low=True)
        integer(self, "seed", low=0, high=2**63 - 1)
        flag(self, "exact")
        flag(self, "joint_states")
        number(self, "truth_rate_hz", low=0.0, open_low=True, high=self.rate_hz)
        ratio = self.rate_hz / self.truth_rate_hz
        if abs(ratio - round(ratio)) > 1e-9:
            raise ParameterError(
                "truth_rate_hz", f"rate_hz / truth_rate_hz = {ratio:g} must be an integer"
            )
        n_rollers = self.actuator.preset.geometry.n_rollers
        seen: set[int] = set()
        for i, jam in enumerate(self.jams):
            if jam.roller > n_rollers:
                raise ParameterError(f"jams[{i}].roller", f"must be <= n_rollers = {n_rollers}")
            if jam.roller in seen:
                raise ParameterError(f"jams[{i}].roller", f"roller {jam.roller} already jams")
            seen.add(jam.roller)
        if isinstance(self.profile, DownholeCycle):
            try:
                self.profile.check(self.actuator.preset.geometry.lead_m)
            except ParameterError as exc:
                raise prefixed(exc, "profile") from exc

    @property
    def samples(self) -> int:
        """Number of motor samples: round(duration * rate)."""
        return round(self.duration_s * self.rate_hz)

    @property
    def truth_decimation(self) -> int:
        """Motor samples per truth sample."""
        return round(self.rate_hz / self.truth_rate_hz)


_SCALARS = ("name", "description", "duration_s", "rate_hz", "seed", "exact", "truth_rate_hz")
_KEYS = {
    *_SCALARS,
    "actuator",
    "profile",
    "radial_load",
    "load_noise",
    "jams",
    "wear",
    "speed_loop",
    "sensors",
    "sensor_faults",
    "joint_states",
}


def scene_from_mapping(data: dict[str, Any]) -> Scene:
    """Validate a parsed scene document and build the :class:`Scene`."""
    unknown = sorted(set(data) - _KEYS)
    if unknown:
        raise ParameterError(unknown[0], f"unknown key; allowed: {', '.join(sorted(_KEYS))}")
    for key in ("name", "actuator", "duration_s", "profile"):
        if key not in data:
            raise ParameterError(key, "missing from the scene")
    try:
        actuator = actuator_from_mapping(data["actuator"])
    except ParameterError as exc:
        raise prefixed(exc, "actuator") from exc
    return Scene(
        **{key: data[key] for key in _SCALARS if key in data},
        actuator=actuator,
        actuator_yaml=yaml.safe_dump(data["actuator"], sort_keys=False),
        profile=profile_from_mapping(data["profile"]),
        radial_load=radial_load_from_mapping(data.get("radial_load")),
        load_noise=section(LoadNoise, data.get("load_noise"), "load_noise"),
        jams=tuple(
            section(Jam, item, f"jams[{i}]")
            for i, item in enumerate(items(data.get("jams"), "jams"))
        ),
        wear=section(Wear, data.get("wear"), "wear"),
        speed_loop=section(SpeedLoop, data.get("speed_loop"), "speed_loop"),
        sensors=section(Sensors, data.get("sensors"), "sensors"),
        sensor_faults=sensor_faults_from_mapping(data.get("sensor_faults")),
        joint_states=data.get("joint_states", False),
    )


def _bundled() -> Path:
    return Path(str(resources.files("prsm_health.scenes") / "data"))


def _bundled_mapping(name: str) -> dict[str, Any]:
    """The parsed YAML of the bundled scene ``name`` (a fresh dict to modify)."""
    return load_yaml_mapping(_bundled() / f"{name}.yaml")


def varied_scene(base: str, name: str, description: str | None = None, **changes: Any) -> Scene:
    """The bundled scene ``base`` renamed, described (None: the base's description kept) and
    changed by ``changes``: a section given as a mapping is merged into the base's section
    key by key, unless its ``type`` differs (a sine profile in place of a downhole cycle),
    which replaces the section; any other value replaces the key's (None: the format's
    default, e.g. no sensor faults)."""
    mapping = _merged(_bundled_mapping(base), changes) | {"name": name}
    if description is not None:
        mapping["description"] = description
    return scene_from_mapping(mapping)


def _merged(base: dict[str, Any], changes: dict[str, Any]) -> dict[str, Any]:
    """``base`` with ``changes`` as :func:`varied_scene` applies them (a new dict)."""
    merged = dict(base)
    for key, value in changes.items():
        before = base.get(key)
        if (
            isinstance(value, dict)
            and isinstance(before, dict)
            and value.get("type", before.get("type")) == before.get("type")
        ):
            merged[key] = _merged(before, value)
        else:
            merged[key] = value
    return merged


def scene_names() -> tuple[str, ...]:
    """Names of the bundled scenes."""
    return tuple(sorted(p.stem for p in _bundled().glob("*.yaml")))


def load_scene_file(path: Path) -> Scene:
    """Load a scene from a YAML file; errors name the file and the field."""
    try:
        return scene_from_mapping(preset_beside_file(load_yaml_mapping(path), path))
    except YamlError as exc:
        raise ParameterError("scene", str(exc)) from exc
    except ParameterError as exc:
        raise prefixed(exc, str(path), separator=": ") from exc


def load_scene(name_or_path: str) -> Scene:
    """A bundled scene by name, or a scene file by path."""
    bundled = name_or_path in scene_names()
    path = _bundled() / f"{name_or_path}.yaml" if bundled else Path(name_or_path)
    if path.is_file() and path.suffix not in (".yaml", ".yml"):  # e.g. a bag given by mistake
        raise ParameterError("scene", f"{name_or_path}: a scene file is YAML (.yaml or .yml)")
    if not path.is_file():
        raise ParameterError(
            "scene",
            f"unknown scene {name_or_path!r}; a YAML file, or one of {', '.join(scene_names())}",
        )
    return load_scene_file(path)
