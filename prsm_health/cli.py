"""Command-line entry point ``prsm-health``.

Subcommands:
  model       evaluate the PRSM physics at one operating point (table or --json)
  model-demo  the model for every bundled preset at its paper's largest load
  play, monitor, demo   the ROS tools (prsm_health/ros/tools.py)
  simulate    run a scene of the truth simulator into a rosbag2 MCAP bag
  replay      run the estimator over a bag: summary, --out MCAP, --report, --metrics-json
  node-params the node's params file for a simulated bag (its actuator, e.g. its wear)
  bench       the estimator benchmark: run time against error, floors (docs/performance.md)
Units at this edge are the engineers' ones (N, rpm, arcmin, mm, um/h); inside all is SI.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import shutil
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

from tqdm import tqdm

from prsm_health.bags.mcap_scan import MAGIC
from prsm_health.bags.writer import working_directory
from prsm_health.bench_command import add_bench_command
from prsm_health.interrupt import EXIT_INTERRUPTED, removed_on_abort, stop_on_interrupt
from prsm_health.node_params import add_node_params_command
from prsm_health.physics.errors import ParameterError, PhysicsError
from prsm_health.physics.geometry import Misalignment
from prsm_health.physics.load_distribution import LoadingCase
from prsm_health.physics.model import ModelResult, OperatingPoint, evaluate
from prsm_health.physics.presets import PRESET_NAMES, load_preset
from prsm_health.replay_command import add_replay_command
from prsm_health.ros.tools import add_ros_commands, number_or_nan
from prsm_health.scenes.recording import record
from prsm_health.scenes.scene import load_scene, scene_names
from prsm_health.scenes.simulator import Simulator

EXIT_USAGE = 2
#: Exit code after the reader of stdout went away (128 + SIGPIPE, as the shell reports it).
EXIT_BROKEN_PIPE = 141
#: Bytes per motor sample of a simulated bag with its truth, a little above those measured
#: (43 on nominal-downhole; 82 with /joint_states, counted as twice this).
BAG_BYTES_PER_SAMPLE = 50
RPM_TO_RAD_S = 2.0 * math.pi / 60.0
M_PER_S_TO_UM_PER_H = 1e6 * 3600.0


#: The option that sets each field of an operating point or scene, for errors that name the
#: field: the user typed ``--axial-load -5``, not ``axial_load_n``.
OPTION_OF_FIELD = {
    "axial_load_n": "--axial-load",
    "radial_load_n": "--radial-load",
    "jammed_rollers": "--jammed",
    "duration_s": "--duration",
    "rate_hz": "--rate",
    "seed": "--seed",
}


def _by_option(exc: ParameterError) -> ParameterError:
    """``exc`` naming the command-line option of its field, where there is one."""
    option = OPTION_OF_FIELD.get(exc.field)
    return exc if option is None else ParameterError(option, exc.message)


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (the usage text is for --help)."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message}\n")


def _finite(text: str) -> float:
    """A finite number (argparse type), refused as ``invalid finite number: '30000k'``."""
    value = number_or_nan(text)
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"invalid finite number: {text!r}")
    return value


def _build_parser() -> _Parser:
    parser = _Parser(
        prog="prsm-health",
        description="Health monitoring of a planetary roller screw actuator: its physics "
        "model, scene simulation, bag replay, benchmark and ROS tools.",
    )
    commands = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    model = commands.add_parser("model", help="evaluate the physics at one operating point")
    model.set_defaults(handler=_run_model)
    model.add_argument(
        "--preset", required=True, help=f"one of {', '.join(PRESET_NAMES)}, or a YAML file"
    )
    model.add_argument(
        "--axial-load", type=_finite, required=True, metavar="N", help="axial load [N]"
    )
    model.add_argument(
        "--radial-load", type=_finite, default=0.0, metavar="N", help="radial load [N] (default 0)"
    )
    model.add_argument(
        "--speed-rpm",
        type=_finite,
        default=300.0,
        metavar="RPM",
        help="screw speed [rpm] (default 300)",
    )
    model.add_argument(
        "--jammed", type=int, default=0, metavar="K", help="jammed rollers (default 0)"
    )
    model.add_argument(
        "--misalignment-arcmin",
        type=_finite,
        nargs=2,
        default=(0.0, 0.0),
        metavar=("X", "Y"),
        help="screw tilt about x and y [arcmin] (default 0 0)",
    )
    model.add_argument(
        "--case",
        type=int,
        choices=(1, 2),
        default=1,
        help="1: screw in tension, nut in compression (as 004); 2: both in compression",
    )
    model.add_argument(
        "--carrier-angle-deg",
        type=_finite,
        default=0.0,
        metavar="DEG",
        help="roller carrier angle against the radial load [deg] (default 0)",
    )
    model.add_argument(
        "--elastic-errors", action="store_true", help="add 000's torsion elastic error"
    )
    model.add_argument(
        "--wear-model",
        choices=("archard", "fractal"),
        help="override the preset's wear law (004 Archard or 001 fractal)",
    )
    model.add_argument("--json", action="store_true", help="print one JSON object")

    simulate = commands.add_parser("simulate", help="simulate a scene into an MCAP bag")
    simulate.set_defaults(handler=_run_simulate)
    simulate.add_argument(
        "--scene", required=True, help=f"one of {', '.join(scene_names())}, or a YAML file"
    )
    simulate.add_argument("--duration", type=_finite, metavar="S", help="override duration_s")
    simulate.add_argument(
        "--rate",
        type=_finite,
        metavar="HZ",
        help="override rate_hz (the truth's rate becomes the largest whole divisor of it up "
        "to the scene's truth_rate_hz)",
    )
    simulate.add_argument("--seed", type=int, metavar="N", help="override the seed")
    simulate.add_argument(
        "--joint-states", action="store_true", help="also write /joint_states (JointState)"
    )
    simulate.add_argument(
        "--exact", action="store_true", help="physics core at every sample (slow), no table"
    )
    simulate.add_argument(
        "--out",
        required=True,
        type=Path,
        metavar="PATH",
        help="bag directory (a bare MCAP file if PATH ends in .mcap)",
    )
    simulate.add_argument("--force", action="store_true", help="replace an existing bag at PATH")

    model_demo = commands.add_parser(
        "model-demo", help="model every bundled preset at its largest paper load"
    )
    model_demo.set_defaults(handler=_run_model_demo)
    add_ros_commands(commands)
    add_replay_command(commands)
    add_node_params_command(commands)
    add_bench_command(commands)
    return parser


def _point(args: argparse.Namespace) -> OperatingPoint:
    return OperatingPoint(
        axial_load_n=args.axial_load,
        radial_load_n=args.radial_load,
        screw_speed_rad_s=args.speed_rpm * RPM_TO_RAD_S,
        jammed_rollers=args.jammed,
        misalignment=Misalignment.from_arcmin(*args.misalignment_arcmin),
        case=LoadingCase(args.case),
        carrier_angle_rad=math.radians(args.carrier_angle_deg),
        elastic_errors=args.elastic_errors,
    )


def result_to_json(preset_name: str, args: dict[str, Any], result: ModelResult) -> dict[str, Any]:
    """The ``model --json`` document: inputs echoed, outputs in engineering units."""
    loads = result.loads
    return {
        "inputs": {"preset": preset_name, **args},
        "contact_force_screw_roller_n": loads.screw_roller_n.tolist(),
        "contact_force_roller_nut_n": loads.roller_nut_n.tolist(),
        "roller_axial_load_n": loads.roller_axial_load_n.tolist(),
        "axial_clearance_mm": (result.meshing.axial_clearance_screw_roller_m * 1e3).tolist(),
        "friction_torque_nm": float(result.friction.total_nm),
        "efficiency": result.efficiency,
        "precision_loss_rate_um_per_h": result.precision_loss_rate_m_per_s * M_PER_S_TO_UM_PER_H,
        "fatigue_life_h": result.fatigue_life_h if math.isfinite(result.fatigue_life_h) else None,
        "solver": {"iterations": loads.iterations, "scaled_residual": loads.residual},
    }


def _table(preset_name: str, result: ModelResult) -> str:
    point, loads = result.point, result.loads
    loss_rate_um_per_h = result.precision_loss_rate_m_per_s * M_PER_S_TO_UM_PER_H
    lines = [
        f"preset {preset_name}: F_a = {point.axial_load_n:.0f} N, F_r = "
        f"{point.radial_load_n:.0f} N, {point.screw_speed_rad_s / RPM_TO_RAD_S:.0f} rpm, "
        f"case {int(point.case)}, {point.jammed_rollers} jammed",
        f"  friction torque          {float(result.friction.total_nm):10.4f} N m",
        f"  efficiency               {result.efficiency:10.4f}",
        f"  precision-loss rate      {loss_rate_um_per_h:10.3g} um/h",
        f"  fatigue life             {_life(result.fatigue_life_h)}",
        f"  peak contact force       {loads.screw_roller_n.max():10.1f} N (screw-roller), "
        f"{loads.roller_nut_n.max():.1f} N (roller-nut)",
        "  roller  axial load [N]  screw-roller force, thread 1 .. last [N]",
    ]
    for i, (axial, forces) in enumerate(
        zip(loads.roller_axial_load_n, loads.screw_roller_n, strict=True), start=1
    ):
        lines.append(
            f"  {i:6d}  {axial:14.1f}  {forces[0]:7.1f} .. {forces[-1]:7.1f}  "
            f"(min {forces.min():.1f}, max {forces.max():.1f})"
        )
    return "\n".join(lines)


def _life(hours: float) -> str:
    """A fatigue life for the table: none at standstill, where nothing rolls over."""
    return f"{hours:10.4g} h" if math.isfinite(hours) else "         - (no rotation)"


def _run_model(args: argparse.Namespace) -> int:
    preset = load_preset(args.preset)
    if args.wear_model:
        preset = dataclasses.replace(
            preset, wear=dataclasses.replace(preset.wear, model=args.wear_model)
        )
    try:
        result = evaluate(preset, _point(args))
    except ParameterError as exc:
        raise _by_option(exc) from exc
    if args.json:
        echoed = {
            k: v for k, v in vars(args).items() if k not in ("command", "handler", "json", "preset")
        }
        echoed["misalignment_arcmin"] = list(args.misalignment_arcmin)
        echoed["wear_model"] = preset.wear.model  # the law used, the preset's unless given
        print(json.dumps(result_to_json(preset.name, echoed, result)))
    else:
        print(_table(preset.name, result))
    return 0


def _run_model_demo(_args: argparse.Namespace) -> int:
    for name in PRESET_NAMES:
        preset = load_preset(name)
        point = OperatingPoint(
            axial_load_n=preset.largest_axial_load_n,
            radial_load_n=preset.largest_radial_load_n / 2.0,
            screw_speed_rad_s=preset.largest_speed_rpm * RPM_TO_RAD_S,
        )
        print(_table(name, evaluate(preset, point)))
        print()
    return 0


def _check_room(samples: int, *, joint_states: bool, out: Path) -> None:
    """Refuse a bag that would not fit on the disk of ``out`` (estimated from
    BAG_BYTES_PER_SAMPLE), before hours of simulation fill it."""
    per_sample = BAG_BYTES_PER_SAMPLE * (2 if joint_states else 1)
    needed = samples * per_sample
    existing = next(p for p in (out.absolute(), *out.absolute().parents) if p.exists())
    free = shutil.disk_usage(existing).free
    if needed > free:
        raise ValueError(
            f"--out: {samples} samples would take about {needed / 1e9:.3g} GB "
            f"({per_sample} bytes each), {free / 1e9:.3g} GB are free: shorten --duration"
        )


def _remove_bag(path: Path) -> None:
    """Delete the bag directory or bare ``.mcap`` file ``path`` (--force); refuse anything
    that is not a bag (a symbolic link too: what it points to is not ours to delete)."""
    if path.is_symlink():
        raise ValueError(f"--force: {path} is a symbolic link, not a bag (not removed)")
    if path.suffix == ".mcap" and path.is_file():
        with path.open("rb") as stream:
            if stream.read(len(MAGIC)) != MAGIC:
                raise ValueError(f"--force: {path} is not an MCAP file (not removed)")
        path.unlink()
        return
    files = list(path.iterdir()) if path.is_dir() else []
    if not files or any(f.name != "metadata.yaml" and f.suffix != ".mcap" for f in files):
        raise ValueError(f"--force: {path} is not a bag directory (metadata.yaml, *.mcap)")
    for file in files:
        file.unlink()
    path.rmdir()


def _remove_killed_write(out: Path) -> None:
    """--force: the working directory that a killed write of the bare MCAP file ``out`` left
    (one bag directory in it), which BagWriter would otherwise refuse to reuse."""
    working = working_directory(out)
    if out.suffix != ".mcap" or working.is_symlink() or not working.is_dir():
        return
    inside = list(working.iterdir())
    if [p.name for p in inside] != [out.stem]:
        raise ValueError(f"--force: {working} holds more than a bag (not removed)")
    _remove_bag(inside[0])
    working.rmdir()


def _run_simulate(args: argparse.Namespace) -> int:
    scene = load_scene(args.scene)
    overrides = {
        "duration_s": args.duration,
        "rate_hz": args.rate,
        "seed": args.seed,
        "joint_states": True if args.joint_states else None,
    }
    if args.rate is not None and args.rate > 0.0:
        overrides["truth_rate_hz"] = args.rate / math.ceil(args.rate / scene.truth_rate_hz)
    try:
        scene = dataclasses.replace(scene, **{k: v for k, v in overrides.items() if v is not None})
    except ParameterError as exc:
        raise _by_option(exc) from exc
    _check_room(scene.samples, joint_states=scene.joint_states, out=args.out)
    if args.out.exists() or args.out.is_symlink():
        if not args.force:
            raise ValueError(f"{args.out} exists (use --force to replace a bag)")
        _remove_bag(args.out)
    if args.force:
        _remove_killed_write(args.out)
    if late := [f"{jam.time_s:g} s" for jam in scene.jams if jam.time_s >= scene.duration_s]:
        print(
            f"note: the jam(s) at {', '.join(late)} come after the end of the run "
            f"({scene.duration_s:g} s): not simulated",
            file=sys.stderr,
        )
    simulator = Simulator(scene, exact=True if args.exact else None)
    with (
        stop_on_interrupt() as stop,
        removed_on_abort(args.out),
        tqdm(total=scene.samples, unit="sample", unit_scale=True, disable=None) as bar,
    ):
        motor, truth = record(simulator, args.out, progress=bar.update, stop=stop)
    print(f"{args.out}: scene {scene.name}, {motor} motor samples, {truth} truth samples")
    if stop.is_set():
        seconds = motor / scene.rate_hz
        print(f"interrupted: the bag holds the first {seconds:g} s of {scene.duration_s:g} s")
        return EXIT_INTERRUPTED
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``prsm-health``; physics errors become a one-line message and exit code 2."""
    args = _build_parser().parse_args(argv)
    try:
        return int(args.handler(args))
    except (PhysicsError, ValueError) as exc:
        print(f"prsm-health: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:  # a second Ctrl-C (the first asks to stop: interrupt.py)
        print("prsm-health: aborted by Ctrl-C", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # the reader left (``| head``): stop quietly, as cat does
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_BROKEN_PIPE


if __name__ == "__main__":
    sys.exit(main())
