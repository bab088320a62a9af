"""The node's parameters: one table (names, defaults, ranges, descriptions) and its validation.

:data:`PARAMETERS` is what the node declares (with ROS descriptors built from it) and what
docs/ros.md and the launch file list. :func:`node_config` turns the values into a validated
:class:`NodeConfig`, naming every bad parameter. Free of ROS nodes: the node builds the
descriptors; only rclpy's topic-name check is used here.

Every parameter but ``autostart`` is applied at configure: while the node is configured
(inactive or active) a change is refused with that reason; in the unconfigured state a value
outside its descriptor (range, type, choices) is refused at once and the rest is checked at
the next configure (so a bad value can be fixed through the lifecycle without a restart).
``autostart`` is read-only (it matters only at start).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from rclpy.exceptions import InvalidTopicNameException
from rclpy.validate_topic_name import validate_topic_name

from prsm_health.estimation.params import (
    EstimatorParams,
    bundled_params_file,
    load_params_mapping,
    params_from_mapping,
)
from prsm_health.outputs import DEFAULT_HARDWARE_ID, hardware_id_problem
from prsm_health.physics.errors import PhysicsError
from prsm_health.ros.persistence import default_state_file
from prsm_health.yamlio import YamlError

PACKAGE = "prsm_health"
NODE_NAME = "prsm_health"
#: A slower ~/health timer than this is refused (its period in ns would overflow rcl's int64
#: near 1e-10 Hz; nobody wants one estimate a minute either).
LOWEST_HEALTH_RATE_HZ = 0.01

Value = bool | int | float | str


@dataclass(frozen=True)
class ParameterSpec:
    """One parameter: its default (which fixes the type), what it means, what it may be."""

    name: str
    default: Value
    description: str
    bounds: tuple[float, float] | None = None
    choices: tuple[str, ...] = ()
    read_only: bool = False

    def problem(self, value: object) -> str | None:
        """Why ``value`` is not allowed (None if it is)."""
        expected = type(self.default)
        if expected is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if type(value) is not expected:
            return f"must be a {expected.__name__}, got {value!r}"
        if self.choices and value not in self.choices:
            return f"must be one of {', '.join(self.choices)}, got {value!r}"
        if self.bounds is not None and isinstance(value, int | float):
            low, high = self.bounds
            if not (math.isfinite(value) and low <= value <= high):
                return f"must be in [{low:g}, {high:g}], got {value!r}"
        return None


PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec(
        "autostart",
        True,
        "configure and activate at start (false: wait for the lifecycle)",
        read_only=True,
    ),
    ParameterSpec(
        "params_file",
        "",
        "estimator parameters YAML (docs/estimation.md); empty: the bundled config/default.yaml",
    ),
    ParameterSpec(
        "preset",
        "",
        "PRSM preset name or YAML path (from the working directory); overrides actuator.preset",
    ),
    ParameterSpec(
        "hardware_id",
        DEFAULT_HARDWARE_ID,
        "actuator id: diagnostics hardware_id and state file name ([A-Za-z0-9_.-]+)",
    ),
    ParameterSpec(
        "input_type",
        "motor_state",
        "input message type",
        choices=("motor_state", "joint_state"),
    ),
    ParameterSpec(
        "input_topic",
        "",
        "input topic; empty: motor_state or joint_states according to input_type",
    ),
    ParameterSpec("joint_name", "prsm_motor", "the motor joint in JointState inputs"),
    ParameterSpec(
        "effort_is",
        "current",
        "JointState effort: motor current [A] or motor torque [N m] (divided by k_t)",
        choices=("current", "torque"),
    ),
    ParameterSpec(
        "input_qos",
        "sensor_data",
        "input QoS: sensor_data (best effort, keeps the last input_queue_depth) or reliable "
        "(keeps all: a full queue holds the publisher back)",
        choices=("sensor_data", "reliable"),
    ),
    ParameterSpec(
        "input_queue_depth",
        1000,
        "best-effort input queue depth [messages] (reliable input keeps all)",
        (1, 100_000),
    ),
    ParameterSpec(
        "batch_period_s",
        0.005,
        "received samples go to the estimator this often [s]",
        (0.001, 0.1),
    ),
    ParameterSpec(
        "health_rate_hz",
        0.0,
        "~/health rate [Hz]; 0: every estimate (one per block)",
        (0.0, 1000.0),
    ),
    ParameterSpec("diagnostics_rate_hz", 1.0, "/diagnostics rate [Hz]", (0.01, 100.0)),
    ParameterSpec(
        "state_file",
        "",
        "estimator state file; empty: $XDG_STATE_HOME/prsm_health/<hardware_id>.json"
        " (~/.local/state by default)",
    ),
    ParameterSpec("save_period_s", 10.0, "state saved this often [s]", (0.1, 86_400.0)),
)
SPECS = {spec.name: spec for spec in PARAMETERS}


def usage() -> str:
    """``prsm-health-node --help``: how to start it and every parameter, from :data:`PARAMETERS`."""
    lines = [
        "usage: prsm-health-node [--ros-args -p NAME:=VALUE ...]",
        "",
        "The PRSM health node: estimates from motor samples, published on ~/health and",
        "/diagnostics (docs/ros.md). Parameters (name, default, allowed values, meaning):",
    ]
    for spec in PARAMETERS:
        allowed = ""
        if spec.choices:
            allowed = f" {{{', '.join(spec.choices)}}}"
        elif spec.bounds is not None:
            allowed = f" [{spec.bounds[0]:g}, {spec.bounds[1]:g}]"
        default = repr(spec.default) if isinstance(spec.default, str) else spec.default
        read_only = "; read-only" if spec.read_only else ""
        lines.append(f"  {spec.name} = {default}{allowed}{read_only}")
        lines.append(f"      {spec.description}")
    lines.append("  use_sim_time = False")
    lines.append(
        "      follow /clock instead of the wall clock (e.g. with prsm-health play --clock)"
    )
    return "\n".join(lines)


InputType = Literal["motor_state", "joint_state"]
EffortIs = Literal["current", "torque"]
InputQos = Literal["sensor_data", "reliable"]


class ConfigError(ValueError):
    """Parameters that cannot be used; ``problems`` maps each parameter to what is wrong."""

    def __init__(self, problems: Mapping[str, str]) -> None:
        super().__init__(
            "; ".join(f"parameter {name}: {problem}" for name, problem in problems.items())
        )
        self.problems = dict(problems)


@dataclass(frozen=True)
class NodeConfig:
    """Validated node configuration (see :data:`PARAMETERS` for each field's meaning)."""

    estimator: EstimatorParams
    params_file: Path
    hardware_id: str
    input_type: InputType
    input_topic: str
    joint_name: str
    effort_is: EffortIs
    input_qos: InputQos
    input_queue_depth: int
    batch_period_s: float
    health_rate_hz: float
    diagnostics_rate_hz: float
    state_file: Path
    save_period_s: float

    @property
    def effort_torque_constant_nm_per_a(self) -> float | None:
        """k_t that turns a JointState effort into the current; None if it is the current."""
        if self.effort_is == "current":
            return None
        return self.estimator.actuator.drive_train.torque_constant_nm_per_a


def _estimator_params(params_file: Path, preset: str) -> EstimatorParams:
    data = load_params_mapping(params_file)
    if preset:
        actuator = data.get("actuator")
        data["actuator"] = {**(actuator if isinstance(actuator, dict) else {}), "preset": preset}
    return params_from_mapping(data)


def _state_file_problem(path: Path) -> str | None:
    """Why ``path`` cannot be the state file, or None: a directory there would be moved aside
    as an unreadable state (with whatever it holds), a file where its folder should be makes
    every save fail."""
    if path.is_dir():
        return f"{path} is a directory; name a file (e.g. {path / 'state.json'})"
    folder = next((p for p in path.parents if p.exists()), None)
    if folder is not None and not folder.is_dir():
        return f"{folder} is not a directory, so {path} cannot be written"
    return None


def node_config(values: Mapping[str, Any], errors: Mapping[str, str] | None = None) -> NodeConfig:
    """Validate the parameter values (name -> value); ``errors``: problems already known
    (e.g. a value ROS refused at declaration). Raises ConfigError naming every bad one."""
    problems = dict(errors or {})
    for spec in PARAMETERS:
        if spec.name not in problems and (problem := spec.problem(values[spec.name])):
            problems[spec.name] = problem
    hardware_id = str(values["hardware_id"])
    if "hardware_id" not in problems and (problem := hardware_id_problem(hardware_id)):
        problems["hardware_id"] = problem
    if "input_topic" not in problems and values["input_topic"]:
        try:
            validate_topic_name(values["input_topic"])
        except InvalidTopicNameException as exc:
            problems["input_topic"] = f"{str(exc).splitlines()[0]} {values['input_topic']!r}"
    rate = values["health_rate_hz"]
    if "health_rate_hz" not in problems and 0.0 < rate < LOWEST_HEALTH_RATE_HZ:
        problems["health_rate_hz"] = (
            f"must be 0 (every estimate) or at least {LOWEST_HEALTH_RATE_HZ:g}, got {rate!r}"
        )
    if problems:
        raise ConfigError(problems)

    params_file = Path(values["params_file"]) if values["params_file"] else bundled_params_file()
    try:
        estimator = _estimator_params(params_file, values["preset"])
    except (YamlError, PhysicsError, ValueError) as exc:
        if values["preset"] and "preset" in getattr(exc, "field", ""):
            raise ConfigError({"preset": str(exc)}) from exc
        named = exc if isinstance(exc, YamlError) else f"{params_file}: {exc}"  # YAML's names it
        raise ConfigError({"params_file": str(named)}) from exc

    input_type = values["input_type"]
    topic = values["input_topic"] or (
        "motor_state" if input_type == "motor_state" else "joint_states"
    )
    state_file = (
        Path(values["state_file"]) if values["state_file"] else default_state_file(hardware_id)
    ).expanduser()
    if problem := _state_file_problem(state_file):
        raise ConfigError({"state_file": problem})
    return NodeConfig(
        estimator=estimator,
        params_file=params_file,
        hardware_id=hardware_id,
        input_type=input_type,
        input_topic=topic,
        joint_name=values["joint_name"],
        effort_is=values["effort_is"],
        input_qos=values["input_qos"],
        input_queue_depth=int(values["input_queue_depth"]),
        batch_period_s=float(values["batch_period_s"]),
        health_rate_hz=float(values["health_rate_hz"]),
        diagnostics_rate_hz=float(values["diagnostics_rate_hz"]),
        state_file=state_file,
        save_period_s=float(values["save_period_s"]),
    )
