"""``prsm-health replay BAG``: the estimator over a bag, with outputs, report and metrics.

Parameters: ``--params FILE`` (estimator YAML, docs/estimation.md), else the bundled
config/default.yaml. The actuator: ``--scene NAME|FILE`` takes the actuator section of a
scene; else a simulated bag's own (recorded in it by ``prsm-health simulate``, or for a bag
without that record the bundled scene it is named after:
:func:`~prsm_health.scenes.recording.bag_actuator`), also over the ``--params`` file's (the
scenes accelerate wear: the estimator must know by how much); else the parameters file's.
A ``--params`` file without an ``actuator:`` section (settings only) takes the scene's.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import math
import sys
from pathlib import Path
from typing import Any

from tqdm import tqdm

from prsm_health.bags import InputTopics
from prsm_health.bags.bagfiles import bag_files
from prsm_health.bags.reader import joint_names
from prsm_health.bags.topics import MOTOR_FRAME
from prsm_health.estimation.estimate import UM_PER_M
from prsm_health.estimation.inputs import RejectReason
from prsm_health.estimation.metrics import Metrics
from prsm_health.estimation.motion_torque import against_motion
from prsm_health.estimation.noise_history import HISTORY_BLOCKS
from prsm_health.estimation.params import (
    EstimatorParams,
    bundled_params_file,
    load_params_mapping,
    params_from_mapping,
)
from prsm_health.estimation.position_speed import disagreement
from prsm_health.estimation.sample_faults import CURRENT_NOISE_BLOCK_SAMPLES
from prsm_health.interrupt import (
    EXIT_INTERRUPTED,
    remove_output,
    removed_on_abort,
    stop_on_interrupt,
)
from prsm_health.output_paths import make_folder, remove_made_folders
from prsm_health.outputs import DEFAULT_HARDWARE_ID, hardware_id_problem, out_of_range_reason
from prsm_health.replay import ReplayResult, replay
from prsm_health.scenes.recording import (
    SceneActuator,
    records_actuator,
    scene_actuator,
    usable_bag_actuator,
)
from prsm_health.yamlio import YamlError


def add_replay_command(commands: Any) -> None:
    """Register ``replay`` on the CLI's subparsers."""
    parser = commands.add_parser("replay", help="run the estimator over a bag (as fast as it can)")
    parser.add_argument("bag", type=Path, help="rosbag2 directory or .mcap file")
    parser.add_argument(
        "--params",
        type=Path,
        metavar="YAML",
        help="estimator parameters (default: the bundled config/default.yaml)",
    )
    parser.add_argument(
        "--scene",
        metavar="NAME|FILE",
        help="take the actuator from a scene (default: the one a simulated bag records)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        metavar="OUT",
        help="write a bag directory (a bare MCAP file if OUT ends in .mcap) with the inputs, "
        "health and diagnostics",
    )
    parser.add_argument("--report", type=Path, metavar="DIR", help="write PNG plots and index")
    parser.add_argument(
        "--metrics-json", type=Path, metavar="FILE", help="write the scores against the truth"
    )
    parser.add_argument(
        "--motor-state-topic",
        default="/motor_state",
        metavar="TOPIC",
        help="the MotorState input (default /motor_state)",
    )
    parser.add_argument(
        "--joint-states", metavar="TOPIC", help="read sensor_msgs/JointState from TOPIC instead"
    )
    parser.add_argument(
        "--joint-name", metavar="NAME", help=f"the motor joint (default {MOTOR_FRAME})"
    )
    parser.add_argument(
        "--effort",
        choices=("current", "torque"),
        help="what JointState.effort carries (default current)",
    )
    parser.add_argument(
        "--hardware-id",
        type=_hardware_id,
        default=DEFAULT_HARDWARE_ID,
        metavar="ID",
        help=f"the diagnostics' hardware_id in --out (default {DEFAULT_HARDWARE_ID}, the node's)",
    )
    parser.set_defaults(handler=run_replay)


def _hardware_id(text: str) -> str:
    """A hardware_id the node would accept (argparse type)."""
    if problem := hardware_id_problem(text):
        raise argparse.ArgumentTypeError(problem)
    return text


def _params(args: argparse.Namespace) -> tuple[EstimatorParams, str, SceneActuator | None]:
    """The estimator parameters, a line saying where they came from, and the scene's actuator
    they hold, if any (module docstring)."""
    path = args.params or bundled_params_file()
    try:
        data = load_params_mapping(path)
    except YamlError as exc:
        raise ValueError(f"--params: {exc}") from exc
    own_actuator = "actuator" in data
    scene = None
    if not own_actuator:  # a file of settings only: the scene's actuator completes it
        scene = _scene_of(args, path)
        if scene is not None:
            data = {**data, "actuator": scene.section}
    try:
        params = params_from_mapping(data)
    except ValueError as exc:  # a bad value: say which file holds it
        raise ValueError(f"--params: {path}: {exc}") from exc
    if own_actuator:
        scene = _scene_of(args, path)
    if scene is None:
        return params, str(path), None
    source = f"{path}, actuator of {scene.origin}"
    if not own_actuator:
        source += " (the file has none)"
    elif args.params is not None and not args.scene:
        source += " instead of the file's (--scene NAME|FILE to choose another)"
    return dataclasses.replace(params, actuator=scene.actuator), source, scene


def _scene_of(args: argparse.Namespace, params_path: Path) -> SceneActuator | None:
    """The actuator of --scene, else the one the bag records (module docstring)."""
    return scene_actuator(args.scene) if args.scene else usable_bag_actuator(args.bag, params_path)


def _check_outputs(args: argparse.Namespace) -> list[Path]:
    """Refuse, before the replay, outputs that could not be written afterwards, and make the
    folders they go into (so that a folder that cannot be made fails now, not after the
    replay); returns the folders made (:func:`~prsm_health.output_paths.make_folder`)."""
    outputs = {
        option: path.resolve()
        for option, path in (
            ("--out", args.out),
            ("--report", args.report),
            ("--metrics-json", args.metrics_json),
        )
        if path is not None
    }
    for (first, a), (second, b) in itertools.combinations(outputs.items(), 2):
        if a == b or a in b.parents or b in a.parents:
            raise ValueError(f"{second}: {b} overlaps {first} {a}")
    bag = args.bag.resolve()
    for option, path in outputs.items():  # a metrics file written over the bag's .mcap
        if path == bag or bag in path.parents:
            raise ValueError(f"{option}: {path} is in the bag being replayed, {bag}")
    if args.out is not None and args.out.exists():
        raise ValueError(f"--out: {args.out} exists")
    if args.report is not None and args.report.exists() and not args.report.is_dir():
        raise ValueError(f"--report: {args.report} exists and is not a directory")
    if args.metrics_json is not None and args.metrics_json.is_dir():
        raise ValueError(f"--metrics-json: {args.metrics_json} is a directory")
    made: list[Path] = []
    try:
        for option, folder in (
            ("--out", None if args.out is None else args.out.parent),
            ("--report", args.report),
            ("--metrics-json", None if args.metrics_json is None else args.metrics_json.parent),
        ):
            if folder is not None:
                made += make_folder(folder, option)
    except ValueError:
        remove_made_folders(made)
        raise
    return made


def _check_options(args: argparse.Namespace) -> None:
    """Refuse options that do not apply."""
    for option, given in (("--joint-name", args.joint_name), ("--effort", args.effort)):
        if given is not None and args.joint_states is None:
            raise ValueError(f"{option}: applies only with --joint-states TOPIC")


def run_replay(args: argparse.Namespace) -> int:
    """Replay the bag, print a summary, write what was asked; 1 if the bag was damaged, 130
    if Ctrl-C stopped it (what was read is reported and written all the same).

    Raises:
        ValueError: an output that cannot be written, or no sample of the bag accepted (the
            summary is printed before the error).
    """
    _check_options(args)
    params, source, scene = _params(args)
    bag_files(args.bag)  # a missing or malformed bag fails here, before any output
    made = _check_outputs(args)
    try:
        return _replay_into_outputs(args, params, source, scene)
    finally:  # those still empty: a run that failed, or wrote nothing there, leaves none
        remove_made_folders(made)


def _replay_into_outputs(
    args: argparse.Namespace, params: EstimatorParams, source: str, scene: SceneActuator | None
) -> int:
    """:func:`run_replay` once the options are checked and the output folders made."""
    topics = InputTopics(
        motor_state=args.motor_state_topic,
        joint_states=args.joint_states,
        joint_name=args.joint_name or MOTOR_FRAME,
        effort=args.effort or "current",
        torque_constant_nm_per_a=(
            params.actuator.drive_train.torque_constant_nm_per_a
            if args.effort == "torque"
            else None
        ),
    )
    try:
        with (
            tqdm(unit="sample", unit_scale=True, disable=None, file=sys.stderr) as bar,
            stop_on_interrupt() as stop,
            removed_on_abort(args.out),
        ):
            result = replay(
                args.bag,
                params,
                topics=topics,
                out=args.out,
                progress=bar.update,
                hardware_id=args.hardware_id,
                stop=stop,
            )
    except ValueError as exc:  # found in the bag after the output was begun (BagError)
        if dropped := _drop_output(args.out):
            raise ValueError(f"{exc}{dropped}") from exc
        raise
    if not result.counters.accepted:
        print(summary(args.bag, source, result))
        why = f"no sample of {args.bag} accepted: {_rejected_why(args.bag, topics, result)}"
        why += _drop_output(args.out)
        if result.damage is not None:  # the damage says more than what it left
            print(f"  {why}")
            return 1
        raise ValueError(why)
    written = [f"bag {args.out}"] if args.out is not None else []
    # The outputs first, the summary after them: a reader that leaves early (``| head``)
    # must not cost the files.
    notes = []
    simulated = result.truth is not None and len(result.truth) > 0
    if scene is None and simulated and not records_actuator(args.bag):
        notes.append(
            f"  note: {args.bag} has a ground truth but no record of its scene's actuator (a"
            " bag cut short loses it): --scene NAME|FILE gives the estimator the scene's"
        )
    try:
        written += _write_outputs(args, result, notes)
    except ValueError:
        print(summary(args.bag, source, result))  # what was replayed, before what failed
        raise
    print("\n".join([summary(args.bag, source, result), *notes]))
    if written:
        print(f"  wrote {', '.join(written)}")
    if result.stopped:
        return EXIT_INTERRUPTED
    return 1 if result.damage is not None else 0


def _write_outputs(args: argparse.Namespace, result: ReplayResult, notes: list[str]) -> list[str]:
    """Write the metrics JSON and the report that ``args`` ask for; returns what was written,
    adds to ``notes`` what was not and why.

    Raises:
        ValueError: an output that cannot be written, naming it.
    """
    written = []
    partial = _partial(result)
    document = None
    if result.metrics is not None:  # the metrics JSON, and the report's index page
        document = {**result.metrics.to_dict(), "samples_read": result.samples}
        document["partial"] = partial or None
    if args.metrics_json is not None:
        if document is None:
            notes.append(f"  --metrics-json: not written, {args.bag} has no ground truth to score")
        else:
            text = json.dumps(document, indent=2, allow_nan=False)
            try:
                args.metrics_json.write_text(text + "\n")
            except OSError as exc:
                raise ValueError(
                    f"--metrics-json: cannot write {args.metrics_json}: {exc}"
                ) from exc
            written.append(f"metrics {args.metrics_json}")
    if args.report is not None:
        from prsm_health.report import write_report  # matplotlib: only when a report is asked

        try:
            title = f"{args.bag.name} ({partial})" if partial else args.bag.name
            write_report(
                args.report,
                result.states,
                result.truth,
                result.metrics,
                title=title,
                scores=document,
            )
        except OSError as exc:
            raise ValueError(f"--report: cannot write into {args.report}: {exc}") from exc
        written.append(f"report {args.report / 'index.html'}")
    return written


def _drop_output(out: Path | None) -> str:
    """Remove the output bag a failed replay began (else it blocks the rerun); what to add to
    the error ("" if there was none)."""
    if out is not None and remove_output(out):
        return f" (the output bag {out} is not kept)"
    return ""


def _partial(result: ReplayResult) -> str:
    """What made the replay cover part of the bag only, for its outputs ("" if nothing)."""
    if result.stopped:
        return f"stopped by Ctrl-C after {result.samples} samples"
    if result.damage is not None and result.inputs_complete:
        return f"the truth up to its damage (all {result.samples} samples read)"
    if result.damage is not None:
        return f"up to the damage after {result.samples} samples"
    return ""


def _rejected_why(bag: Path, topics: InputTopics, result: ReplayResult) -> str:
    """The rejections by reason, and with JointState inputs the joints the bag names (a
    JointState without the joint, naming it twice, or with an effort, velocity or position
    array too short for it, gives a non-finite sample)."""
    if not result.samples:
        return f"no message on {topics.joint_states or topics.motor_state}"
    why = _rejections(result)
    if topics.joint_states is None:
        return f"rejected as {why}"
    names = ", ".join(map(repr, joint_names(bag, topics.joint_states))) or "no joint"
    return (
        f"rejected as {why}; JointState messages on {topics.joint_states} without joint "
        f"{topics.joint_name!r} (--joint-name), naming it twice, or with an effort, velocity "
        f"or position array too short for it give non-finite samples, and the first message "
        f"names {names}"
    )


def _rejections(result: ReplayResult) -> str:
    """The rejected samples by reason (out of range with the fields beyond their range)."""
    counts = result.counters.rejected
    return ", ".join(f"{_reason(r, result)} {counts[r]}" for r in RejectReason if counts[r])


def _reason(reason: RejectReason, result: ReplayResult) -> str:
    if reason == RejectReason.OUT_OF_RANGE:
        return out_of_range_reason(result.measures.out_of_range_by_field)
    return reason.name.lower()


def _current_noise(result: ReplayResult) -> str:
    """The current's noise the input stage measured (its spike threshold's), or why not."""
    noise = result.measures.current_noise_std_a
    if noise is None:
        return f"current noise not measured (no block of {CURRENT_NOISE_BLOCK_SAMPLES} samples)"
    return f"current noise {noise:.3f} A"


def _measured_in_motion(result: ReplayResult) -> str:
    """The speed noise, the position's agreement with the speed and the motor torque along the
    motion, measured in motion, or why they are not."""
    few = f"(under {HISTORY_BLOCKS} blocks in motion)"
    noise, ratio = result.measures.speed_noise_std_rad_s, result.measures.position_per_speed
    parts = [
        f"speed noise not measured {few}" if noise is None else f"speed noise {noise:.2f} rad/s"
    ]
    if ratio is None:
        parts.append(f"position and speed not compared {few}")
    elif (wrong := disagreement(ratio)) is not None:
        parts.append(f"WRONG INPUT: {wrong}")
    else:
        parts.append(f"position per speed {ratio:.2f}")
    forward, reverse = result.measures.torque_along_motion_nm
    if (wrong := against_motion(forward, reverse)) is not None:
        parts.append(f"WRONG INPUT: {wrong}")
    else:
        parts.append(
            f"torque along the motion {_torque(forward)} forward, {_torque(reverse)} reverse"
        )
    return "; ".join(parts)


def _torque(torque_nm: float | None) -> str:
    """A direction's torque along the motion, or that it is not measured yet."""
    return "not measured" if torque_nm is None else f"{torque_nm:+.2f} N·m"


def _count_right(metrics: Metrics) -> str:
    """How often the most likely jam count was the true one, and the largest probability
    given to a wrong one (its bin's lower edge: Metrics.jam_calibration)."""
    bins = metrics.jam_calibration
    estimates = sum(b.estimates for b in bins)
    if not estimates:
        return "no count scored"
    right = sum(b.correct for b in bins)
    said = f"count right in {100.0 * right / estimates:.2f} % of the estimates"
    wrong = [b for b in bins if b.correct < b.estimates]
    return said + (f" (wrong ones at p >= {wrong[-1].low:g})" if wrong else "")


def summary(bag: Path, source: str, result: ReplayResult) -> str:
    """A few lines for the operator: what was read, the last estimate, the scores."""
    counters = result.counters
    rate = result.samples / result.elapsed_s if result.elapsed_s > 0 else float("inf")
    lines = [
        f"{bag}: {result.samples} samples, {len(result.states)} estimates in "
        f"{result.elapsed_s:.2f} s ({rate:,.0f} samples/s); parameters: {source}",
        f"  samples accepted {counters.accepted}, rejected {counters.rejected_total}"
        + (f" ({_rejections(result)})" if counters.rejected_total else "")
        + f"; time resets {counters.time_resets}, gaps {counters.gaps}; "
        + _current_noise(result),
        f"  inputs in motion: {_measured_in_motion(result)}",
    ]
    if result.damage is not None:
        covered = "estimates cover" if result.states else "no estimate from"
        lines.append(f"  DAMAGED: {result.damage} ({covered} what was read before it)")
    if result.stopped:
        lines.append("  STOPPED by Ctrl-C: the estimates and scores cover what was read")
    if result.states:
        last = result.states[-1]
        probabilities = ", ".join(
            f"{k}: {p:.3f}" for k, p in enumerate(last.jam_probabilities) if p >= 1e-3
        )
        lines += [
            f"  last estimate at {last.stamp_s:.2f} s: load {abs(last.axial_load_n) / 1e3:.2f} "
            f"± {last.axial_load_std_n / 1e3:.2f} kN, jammed rollers "
            f"{last.jammed_rollers_most_likely} ({probabilities})",
            f"  precision loss {last.precision_loss_m * UM_PER_M:.3f} ± "
            f"{last.precision_loss_std_m * UM_PER_M:.3f} um, fatigue damage "
            f"{last.fatigue_damage:.3g}",
        ]
    metrics = result.metrics
    if metrics is not None and metrics.estimates_beyond_truth >= len(result.states):
        lines.append(
            f"  vs truth: nothing scored: the {metrics.estimates_beyond_truth} estimates lie "
            "outside the truth's span"
            + (" (stamped on another clock?)" if result.damage is None else "")
        )
    elif metrics is not None:
        delays = ", ".join(
            "never" if j.delay_s is None else f"{j.delay_s:.2f} s" for j in metrics.jams
        )
        jams = f"{len(metrics.jams)} (identified after {delays})" if metrics.jams else "none"
        loss = (
            f"precision loss error {metrics.precision_loss_error_percent:.1f} %"
            if math.isfinite(metrics.precision_loss_error_percent)
            else "no precision loss in the truth to compare"
        )
        nees = {
            True: f"NEES {metrics.load_nees_mean:.2f} (consistent)",
            False: f"NEES {metrics.load_nees_mean:.2f} (NOT consistent)",
            None: "no NEES (no load of 5 % of rated in motion)",
        }[metrics.load_nees_consistent]
        load = (
            f"load RMSE {metrics.load_rmse_percent_rated:.2f} % of rated "
            f"(max {metrics.load_max_error_n:.0f} N), {nees}"
            if math.isfinite(metrics.load_rmse_percent_rated)
            else "no load estimate in motion to score"
        )
        lines.append(f"  vs truth: {load}")
        if math.isfinite(metrics.load_standstill_rmse_n):  # hardly observed: its band matters
            lines.append(
                f"  load at standstill: RMSE {metrics.load_standstill_rmse_n:.0f} N "
                f"(max {metrics.load_standstill_max_error_n:.0f} N), truth within 2 sigma "
                f"{100 * metrics.load_standstill_coverage_2sigma:.0f} % of its estimates"
            )
        coverage = metrics.precision_loss_coverage_2sigma
        lines.append(
            f"  jams: {jams}, false declarations {metrics.false_jam_declarations}, "
            f"{_count_right(metrics)}; {loss}"
            + (f", 2-sigma coverage {100 * coverage:.0f} %" if math.isfinite(coverage) else "")
        )
        if metrics.estimates_beyond_truth:
            lines.append(
                f"  {metrics.estimates_beyond_truth} estimates outside the truth's span are "
                "not scored"
            )
    return "\n".join(lines)
