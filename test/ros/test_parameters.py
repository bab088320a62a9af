"""The node's parameter table and its validation (no ROS needed)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from prsm_health.estimation.params import bundled_params_file
from prsm_health.outputs import CONFIGURATION, PERSISTENCE, STATUS_NAMES
from prsm_health.ros.parameters import (
    PARAMETERS,
    SPECS,
    ConfigError,
    node_config,
)

REPO = Path(__file__).resolve().parents[2]


def values(**changes: Any) -> dict[str, Any]:
    return {**{spec.name: spec.default for spec in PARAMETERS}, **changes}


def test_defaults_make_a_valid_config() -> None:
    config = node_config(values(state_file="/var/lib/x.json"))
    assert config.params_file == bundled_params_file() == REPO / "config" / "default.yaml"
    assert config.estimator.actuator.preset.name == "dong2022-downhole"
    assert config.input_topic == "motor_state"
    assert config.health_rate_hz == 0.0
    assert config.state_file == Path("/var/lib/x.json")


def test_input_topic_follows_the_input_type() -> None:
    assert node_config(values(input_type="joint_state")).input_topic == "joint_states"
    assert node_config(values(input_topic="/a/b")).input_topic == "/a/b"


def test_every_bad_parameter_is_named() -> None:
    with pytest.raises(ConfigError) as info:
        node_config(
            values(health_rate_hz=-1.0, input_type="can", hardware_id="a/b", save_period_s=True)
        )
    assert set(info.value.problems) == {
        "health_rate_hz",
        "input_type",
        "hardware_id",
        "save_period_s",
    }
    message = str(info.value)
    assert "parameter health_rate_hz: must be in [0, 1000], got -1.0" in message
    assert "parameter input_type: must be one of motor_state, joint_state" in message


def test_a_bad_topic_name_and_a_health_rate_near_zero_are_named() -> None:
    """Both passed their descriptors and then broke activate without naming the parameter
    (rcl checks a topic name only when it is used; a period of 1/1e-12 s overflows int64)."""
    with pytest.raises(ConfigError) as info:
        node_config(values(input_topic="bad topic!", health_rate_hz=1e-12))
    assert set(info.value.problems) == {"input_topic", "health_rate_hz"}
    assert info.value.problems["input_topic"].startswith("Invalid topic name")
    assert "'bad topic!'" in info.value.problems["input_topic"]
    assert "must be 0 (every estimate) or at least 0.01" in info.value.problems["health_rate_hz"]
    assert node_config(values(input_topic="~/in", health_rate_hz=0.01)).health_rate_hz == 0.01


def test_errors_known_from_ros_are_reported() -> None:
    with pytest.raises(ConfigError, match="parameter diagnostics_rate_hz: refused"):
        node_config(values(), {"diagnostics_rate_hz": "refused by ROS"})


def test_preset_override_and_its_errors() -> None:
    config = node_config(values(preset="li2020-jamming"))
    assert config.estimator.actuator.preset.name == "li2020-jamming"
    with pytest.raises(ConfigError) as info:
        node_config(values(preset="no-such-preset"))
    assert list(info.value.problems) == ["preset"]


def test_params_file_errors_name_the_file_once(tmp_path: Path) -> None:
    """A YAML error named it twice ("params_file: /x.yaml: /x.yaml, line 4, ...")."""
    missing = tmp_path / "missing.yaml"
    bad = tmp_path / "bad.yaml"
    bad.write_text("actuator: {preset: dong2022-downhole}\nfilter: {gate_nis: -1}\n")
    broken = tmp_path / "broken.yaml"
    broken.write_text("actuator: {preset: [\n")
    for path, problem in (
        (missing, f"cannot read {missing}"),
        (bad, f"{bad}: filter.gate_nis"),
        (broken, f"{broken}, line 2, column 1"),
    ):
        with pytest.raises(ConfigError) as info:
            node_config(values(params_file=str(path)))
        assert info.value.problems["params_file"].startswith(problem)
        assert str(info.value).count(str(path)) == 1


def test_ranges_accept_integers_for_doubles_but_not_bools() -> None:
    assert SPECS["health_rate_hz"].problem(5) is None
    assert SPECS["health_rate_hz"].problem(True) is not None
    assert SPECS["input_queue_depth"].problem(0) is not None
    assert SPECS["autostart"].read_only


def test_docs_list_every_parameter_and_status() -> None:
    docs = (REPO / "docs" / "ros.md").read_text()
    ros_types = {bool: "bool", int: "int", float: "double", str: "string"}
    for spec in PARAMETERS:
        assert f"| `{spec.name}` | {ros_types[type(spec.default)]} |" in docs
    for name in (*STATUS_NAMES, PERSISTENCE, CONFIGURATION):
        assert f"| `{name}` |" in docs


def test_a_state_file_that_is_a_directory_or_under_a_file_is_refused(tmp_path: Path) -> None:
    """A directory there was moved aside as an unreadable state file, with everything in it
    (other actuators' states); a file where its folder should be failed with a bare
    NotADirectoryError."""
    with pytest.raises(ConfigError, match=rf"parameter state_file: {tmp_path} is a directory"):
        node_config(values(state_file=str(tmp_path)))
    a_file = tmp_path / "a-file"
    a_file.write_text("")
    with pytest.raises(ConfigError, match=rf"state_file: {a_file} is not a directory"):
        node_config(values(state_file=str(a_file / "state.json")))


def test_every_range_includes_its_bounds() -> None:
    """Pins that each bounded parameter takes both of its bounds, as --help and docs/ros.md
    print them ([low, high]), and refuses what lies past them. A mutation review found the
    upper bound unguarded (health_rate_hz 1000 refused)."""
    for spec in PARAMETERS:
        if spec.bounds is None:
            continue
        kind = type(spec.default)
        low, high = (kind(bound) for bound in spec.bounds)
        assert spec.problem(low) is None and spec.problem(high) is None, spec.name
        step = 1 if kind is int else high * 1e-9
        assert spec.problem(high + step) == f"must be in [{low:g}, {high:g}], got {high + step!r}"


def test_a_joint_state_effort_is_divided_by_k_t_only_when_it_is_a_torque() -> None:
    """Pins effort_is: a current is used as it is, a torque divided by the drive train's k_t.
    A mutation review found the current case unguarded (divided by k_t as well, the estimates
    of a JointState carrying currents were off by 1/k_t)."""
    assert node_config(values(effort_is="current")).effort_torque_constant_nm_per_a is None
    config = node_config(values(effort_is="torque"))
    k_t = config.estimator.actuator.drive_train.torque_constant_nm_per_a
    assert config.effort_torque_constant_nm_per_a == k_t > 0.0
