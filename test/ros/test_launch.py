"""launch/prsm_health.launch.py against what the package installs and the node declares.

launch_ros is not on PyPI, so the launch file cannot run here: it is parsed (ast) instead, and
its package, executable, node name and parameter names are checked against setup.py and a
real node's declared parameters.
"""

from __future__ import annotations

import ast
from pathlib import Path

import rclpy

from prsm_health.ros.node import HealthNode
from prsm_health.ros.parameters import NODE_NAME, PACKAGE, PARAMETERS

REPO = Path(__file__).resolve().parents[2]
LAUNCH = REPO / "launch" / "prsm_health.launch.py"


def _node_call(tree: ast.Module) -> ast.Call:
    calls = [
        n
        for n in ast.walk(tree)
        if isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id == "Node"
    ]
    assert len(calls) == 1
    return calls[0]


def _keyword(call: ast.Call, name: str) -> object:
    return ast.literal_eval(next(k.value for k in call.keywords if k.arg == name))


def _arguments(tree: ast.Module) -> dict[str, str]:
    """name -> default of the launch arguments."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "ARGUMENTS" for t in node.targets
        ):
            assert isinstance(node.value, ast.Tuple)
            pairs = [ast.literal_eval(ast.Tuple(e.elts[:2])) for e in node.value.elts]  # type: ignore[attr-defined]
            assert len(pairs) == len(dict(pairs))
            return dict(pairs)
    raise AssertionError("no ARGUMENTS in the launch file")


def test_launch_file_names_the_installed_executable_and_node() -> None:
    tree = ast.parse(LAUNCH.read_text())
    call = _node_call(tree)
    assert _keyword(call, "package") == PACKAGE
    assert _keyword(call, "name") == NODE_NAME
    executable = _keyword(call, "executable")
    setup = (REPO / "setup.py").read_text()
    assert f'f"{executable} = {{PACKAGE}}.ros.node:main"' in setup
    assert '"launch"' in setup  # installed to share/prsm_health/launch


def test_launch_arguments_are_node_parameters(ros: None) -> None:
    defaults = _arguments(ast.parse(LAUNCH.read_text()))
    names = list(defaults)
    for spec in PARAMETERS:  # the node's default, as a launch argument writes it
        written = defaults[spec.name]
        kind = type(spec.default)
        value = {"true": True, "false": False}[written] if kind is bool else kind(written)
        assert value == spec.default, spec.name
    node = HealthNode(parameter_overrides=[])
    try:
        declared = set(node.list_parameters([], 0).names)
    finally:
        node.destroy_node()
    assert {spec.name for spec in PARAMETERS} | {"use_sim_time"} <= declared
    assert set(names) == {spec.name for spec in PARAMETERS} | {"use_sim_time"}  # every one


def test_node_declares_descriptors(ros: None) -> None:
    node = HealthNode()
    try:
        rate = node.describe_parameter("health_rate_hz")
        assert rate.floating_point_range[0].from_value == 0.0
        assert rate.description
        assert node.describe_parameter("autostart").read_only
        assert "motor_state" in node.describe_parameter("input_type").additional_constraints
    finally:
        node.destroy_node()
    assert rclpy.ok()
