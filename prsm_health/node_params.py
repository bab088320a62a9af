"""The node's parameters file for a simulated bag: ``prsm-health node-params BAG --out FILE``.

A scene bag records the actuator it was simulated with (scenes/recording.py), and the scenes
accelerate wear (``wear_acceleration``, 1e5 in the bundled ones). A node fed from such a bag
with the bundled parameters estimates the right load and jams but a precision loss that many
times too small. This writes the estimator parameters (the bundled ``config/default.yaml``,
or ``--params FILE``) with the bag's ``actuator:`` section instead of theirs, for the node's
``params_file`` (what ``prsm-health demo`` does for itself).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import yaml

from prsm_health.estimation.params import (
    bundled_params_file,
    load_params_mapping,
    params_from_mapping,
)
from prsm_health.output_paths import make_folder, remove_made_folders
from prsm_health.physics.errors import ParameterError
from prsm_health.scenes.recording import SceneActuator, bag_actuator
from prsm_health.yamlio import YamlError


def params_with_actuator(base: Path, scene: SceneActuator) -> dict[str, Any]:
    """The parameters of ``base`` with the actuator of ``scene`` instead of theirs, checked as
    the node will check them. A file with an ``actuator:`` section of its own is checked with
    it first, as ``prsm-health replay`` checks it before taking the scene's: a mistake in a
    section that is replaced is still a mistake in the file.

    Raises:
        YamlError: ``base`` cannot be read.
        ParameterError: a key or value of ``base`` that the node would refuse.
    """
    params = load_params_mapping(base)
    if "actuator" in params:
        params_from_mapping(params)
    params["actuator"] = scene.section
    params_from_mapping(params)
    return params


def accelerated_wear_note(bag: Path) -> str | None:
    """What ``prsm-health play`` says before playing a bag whose recorded scene accelerates
    wear (None for any other bag, also one whose record cannot be read)."""
    try:
        scene = bag_actuator(bag)
    except ValueError:  # BagError, ParameterError: play says what it can
        return None
    if scene is None or scene.actuator.wear_acceleration == 1.0:
        return None
    return (
        f"note: the scene of {bag} accelerates wear x{scene.actuator.wear_acceleration:g}; a "
        f"node's precision loss follows it only with the bag's actuator: prsm-health "
        f"node-params {bag} --out FILE, then -p params_file:=FILE"
    )


def add_node_params_command(commands: Any) -> None:
    """Register ``node-params`` on the ``prsm-health`` subparsers."""
    parser = commands.add_parser(
        "node-params", help="write the node's params file for a simulated bag (its actuator)"
    )
    parser.add_argument("bag", type=Path, help="a bag made by prsm-health simulate")
    parser.add_argument("--out", required=True, type=Path, metavar="FILE", help="YAML to write")
    parser.add_argument(
        "--params",
        type=Path,
        metavar="YAML",
        help="the estimator parameters to start from (default: the bundled config/default.yaml)",
    )
    parser.set_defaults(handler=_run_node_params)


def _run_node_params(args: argparse.Namespace) -> int:
    """Write the file; a problem is a ValueError (one line, exit 2, from cli.main)."""
    base = args.params or bundled_params_file()
    if args.out.exists():
        raise ValueError(f"--out: {args.out} exists")
    scene = bag_actuator(args.bag)  # a record that builds no actuator: its error, as it is
    if scene is None:
        raise ValueError(
            f"{args.bag} records no actuator (not made by prsm-health simulate, nor named "
            f"after a bundled scene): the node's params_file is {base} or one of yours"
        )
    try:
        params = params_with_actuator(base, scene)
    except YamlError as exc:
        raise ValueError(f"--params: {exc}") from exc
    except ParameterError as exc:  # what the node would refuse at configure
        raise ValueError(f"--params: {base}: {exc}") from exc
    made = make_folder(args.out.parent, "--out")
    try:
        args.out.write_text(yaml.safe_dump(params, sort_keys=False), encoding="utf-8")
    except OSError as exc:
        remove_made_folders(made)
        raise ValueError(f"--out: cannot write {args.out}: {exc}") from exc
    print(
        f"wrote {args.out}: {base} with the actuator of {scene.origin} (wear x "
        f"{scene.actuator.wear_acceleration:g}); start the node with "
        f"--ros-args -p params_file:={args.out.resolve()}"
    )
    return 0
