"""Offline replay over real MCAP bags: outputs, report, metrics, JointState input, damage."""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import re
import shutil
import signal
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from mcap_ros2.reader import read_ros2_messages
from rosbags.rosbag2 import Reader

from prsm_health import replay as replay_module
from prsm_health import replay_command
from prsm_health.bags import MOTOR_STATE, InputTopics, read_motor_samples, read_truth
from prsm_health.bags.bagfiles import custom_data
from prsm_health.bags.topics import DIAGNOSTICS_TOPIC, HEALTH_TOPIC, TRUTH_TOPIC
from prsm_health.bags.typestore import typestore
from prsm_health.bags.writer import BagWriter, write_joint_states, write_motor_states, write_truth
from prsm_health.cli import main
from prsm_health.estimation.estimate import EstimateEvent
from prsm_health.estimation.inputs import InputMeasures
from prsm_health.estimation.metrics import CalibrationBin
from prsm_health.estimation.params import EstimatorParams
from prsm_health.outputs import INPUT_HEALTH
from prsm_health.replay import ReplayResult, replay
from prsm_health.report import (
    PLOTS,
    SHOWN_PROBABILITY,
    _band,
    _counts_shown,
    _estimates_span,
    _load_figure,
    _series,
    _time_label,
    plt,
    write_report,
)
from prsm_health.ros.parameters import SPECS
from prsm_health.scenes.recording import record
from prsm_health.scenes.scene import load_scene, scene_from_mapping
from prsm_health.scenes.simulator import Simulator
from prsm_health.signals import MotorSamples
from test.bags.samples import motor_samples, split_bag, write_bag
from test.test_outputs import state

BUNDLED_BAGS = Path(__file__).resolve().parents[1] / "bags"

SCENE = {
    "name": "replay-test",
    "actuator": {"preset": "dong2022-downhole", "wear_acceleration": 1.0e5},
    "duration_s": 12.0,
    "seed": 3,
    "profile": {
        "type": "downhole_cycle",
        "stroke_m": 0.05,
        "speed_rpm": 400.0,
        "traction_load_n": [20000.0, 40000.0],
        "support_s": 0.5,
    },
    "radial_load": {"type": "wall", "min_n": 2000.0, "max_n": 5000.0, "period_s": 4.0},
    "jams": [{"time_s": 1.5, "roller": 3}],  # mid-stroke
    "joint_states": True,
}


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("bags") / "replay-test"
    record(Simulator(scene_from_mapping(SCENE)), path)
    return path


def params() -> EstimatorParams:
    return EstimatorParams(actuator=scene_from_mapping(SCENE).actuator)


def test_replay_estimates_scores_and_writes_what_the_node_publishes(
    bag: Path, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    result = replay(bag, params(), out=out)
    assert result.damage is None and result.samples == 12_000
    assert result.metrics is not None
    (jam,) = result.metrics.jams
    assert jam.delay_s is not None and jam.delay_s < 0.5
    assert result.metrics.load_rmse_percent_rated < 2.0
    # The scene's drive differences a 4096-count encoder into the speed: about 0.47 rad/s
    # (docs/performance.md, "The drive's sensors"), measured in motion.
    noise = result.measures.speed_noise_std_rad_s
    assert noise is not None
    assert 0.4 < noise < 0.55
    store = typestore()
    with Reader(out) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        health = [
            store.deserialize_cdr(raw, c.msgtype)
            for c, _, raw in reader.messages()
            if c.topic == HEALTH_TOPIC
        ]
    assert counts["/motor_state"] == 12_000
    assert counts[TRUTH_TOPIC] == len(read_truth(bag))  # to view beside the estimates
    assert counts[HEALTH_TOPIC] == len(result.states)
    assert 8 <= counts[DIAGNOSTICS_TOPIC] <= 13  # once per second of the 12 s bag
    last = health[-1]
    assert last.jammed_rollers_most_likely == 1
    assert list(last.jammed_rollers_probability) == pytest.approx(
        list(result.states[-1].jam_probabilities)
    )
    for message in health:
        assert math.isfinite(message.axial_load_n) and message.axial_load_n >= 0.0
    # The embedded schemas let the mcap reader decode everything too.
    decoded = list(read_ros2_messages(out / "out.mcap"))
    assert len(decoded) == sum(counts.values())
    # Under the node's default hardware_id, so that one monitor --hardware-id reads both
    # (the replay's was "prsm_health").
    hardware_ids = {
        status.hardware_id
        for message in decoded
        if message.channel.topic == DIAGNOSTICS_TOPIC
        for status in message.ros_msg.status
    }
    assert hardware_ids == {SPECS["hardware_id"].default}
    last_inputs = [
        status
        for message in decoded
        if message.channel.topic == DIAGNOSTICS_TOPIC
        for status in message.ros_msg.status
        if status.name == INPUT_HEALTH
    ][-1]
    values = {kv.key: kv.value for kv in last_inputs.values}
    assert float(values["speed_noise_std_rad_s"]) == pytest.approx(
        result.measures.speed_noise_std_rad_s, rel=1e-3
    )


def test_diagnostics_come_once_per_second_at_10_khz(tmp_path: Path) -> None:
    """Pieces of 1000 samples are 0.1 s at 10 kHz: the diagnostics still come once per second
    of the inputs' clock, and once more at the end. (A write up to a quarter period early
    looked like the clock going back, so the next piece wrote again: pairs 0.1 s apart, and
    the last one twice; found by a review session.)"""
    bag, out = tmp_path / "fast", tmp_path / "out.mcap"
    scene = {**SCENE, "duration_s": 4.0, "rate_hz": 10_000.0, "joint_states": False}
    record(Simulator(scene_from_mapping(scene)), bag)
    replay(bag, params(), out=out)
    with out.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        seconds = np.array(
            [
                decoded.header.stamp.sec + 1e-9 * decoded.header.stamp.nanosec
                for _, channel, _, decoded in reader.iter_decoded_messages()
                if channel.topic == DIAGNOSTICS_TOPIC
            ]
        )
    spacing = np.diff(seconds)
    assert np.all((spacing[:-1] > 0.9) & (spacing[:-1] < 1.1)), seconds
    assert 0.0 < spacing[-1] < 1.1 and seconds[-1] == pytest.approx(4.0, abs=1e-3), seconds


def test_the_summary_says_when_no_estimate_lies_on_the_truths_clock(
    bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Inputs stamped on the epoch, the truth from 0: nothing can be scored, and the summary
    says so in one line. (It printed "jams: none" for a truth with a jam and a coverage of
    "nan %"; found by a review session.)"""
    motor, truth = read_motor_samples(bag, InputTopics()), read_truth(bag)
    epoch = tmp_path / "epoch"
    with BagWriter(epoch) as writer:
        for key, value in custom_data(bag).items():  # the scene's actuator
            writer.set_custom_data(key, value)
        write_motor_states(writer, dataclasses.replace(motor, stamp_s=motor.stamp_s + 1.7e9))
        write_truth(writer, truth)
    assert main(["replay", str(epoch)]) == 0
    out = capsys.readouterr().out
    estimates = len(replay(epoch, params()).states)
    assert f"vs truth: nothing scored: the {estimates} estimates lie outside the truth's" in out
    assert "nan" not in out and "jams:" not in out


def test_the_output_bag_gives_back_the_inputs_in_their_order(tmp_path: Path) -> None:
    """The bundled sensor-faults bag, whose stamps jump back by 0.5 s at 40 s: its output bag
    holds the same input samples in the same order, and every topic's log times never go
    back. (Each written piece took its log times from its own stamps: 698 samples after the
    jump came back in another order, and a replay of the output fed the estimator another
    stream; found by a review session.)"""
    bag, out = BUNDLED_BAGS / "sensor-faults", tmp_path / "out"
    replay(bag, EstimatorParams(actuator=load_scene("sensor-faults").actuator), out=out)
    given, written = read_motor_samples(bag, InputTopics()), read_motor_samples(out, InputTopics())
    for field in ("stamp_s", "current_a", "speed_rad_s", "position_rad"):
        np.testing.assert_array_equal(getattr(written, field), getattr(given, field))
    with Reader(out) as reader:
        log_times: dict[str, list[int]] = {}
        for connection, log_time, _ in reader.messages():
            log_times.setdefault(connection.topic, []).append(log_time)
    for topic in ("/motor_state", HEALTH_TOPIC, DIAGNOSTICS_TOPIC):
        assert np.all(np.diff(log_times[topic]) >= 0), topic


def test_cli_out_ending_in_mcap_writes_the_bag_as_a_bare_mcap_file(
    bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--out OUT.mcap`` (the issue's usage, what Foxglove opens): the MCAP of ``--out OUT``,
    byte for byte. It was refused, since a bag is a directory."""
    directory, bare = tmp_path / "out", tmp_path / "out.mcap"
    assert main(["replay", str(bag), "--out", str(directory)]) == 0
    assert main(["replay", str(bag), "--out", str(bare)]) == 0
    assert f"wrote bag {bare}" in capsys.readouterr().out
    assert bare.read_bytes() == (directory / "out.mcap").read_bytes()
    topics = {m.channel.topic for m in read_ros2_messages(bare)}
    assert {HEALTH_TOPIC, DIAGNOSTICS_TOPIC, TRUTH_TOPIC, "/motor_state"} <= topics


def test_joint_state_input_gives_the_same_estimates(bag: Path) -> None:
    from_motor_state = replay(bag, params())
    from_joint_states = replay(bag, params(), topics=InputTopics(joint_states="/joint_states"))
    assert len(from_joint_states.states) == len(from_motor_state.states)
    a = np.array([s.axial_load_n for s in from_motor_state.states])
    b = np.array([s.axial_load_n for s in from_joint_states.states])
    # JointState stamps come from the same clock; the speed and current are the same numbers.
    np.testing.assert_allclose(b, a, rtol=1e-6, atol=1e-3)


def test_a_truncated_bag_reports_what_was_read_and_names_the_damage(
    bag: Path, tmp_path: Path
) -> None:
    damaged = tmp_path / "replay-test"
    shutil.copytree(bag, damaged)
    mcap = damaged / "replay-test.mcap"
    mcap.write_bytes(mcap.read_bytes()[: int(mcap.stat().st_size * 0.7)])
    result = replay(damaged, params())
    assert result.damage is not None and str(mcap) in str(result.damage)
    assert 0 < result.samples < 12_000
    assert result.states and result.states[-1].stamp_s > 2.0


def test_the_report_draws_the_estimates_on_the_truths_clock_after_a_time_reset() -> None:
    # The bundled sensor-faults bag: its header stamps jump back by 0.5 s at 40 s.
    result = replay(
        BUNDLED_BAGS / "sensor-faults",
        EstimatorParams(actuator=load_scene("sensor-faults").actuator),
    )
    assert result.metrics is not None and result.truth is not None
    truth = result.truth
    offsets = result.metrics.clock_offsets_s
    assert offsets == pytest.approx((0.0, 0.5), abs=0.01)  # the dropout at 9 s, the reset
    reset = [i for i, s in enumerate(result.states) if s.event == EstimateEvent.TIME_RESET]
    assert len(reset) == 1
    after = slice(reset[0], None)
    drawn, on_sensor_clock = _series(result.states, offsets), _series(result.states, None)

    def rms_error_kn(series_stamps: np.ndarray, load_kn: np.ndarray) -> float:
        true_kn = np.interp(series_stamps, truth.stamp_s, truth.axial_load_n / 1e3)
        return float(np.sqrt(np.mean((load_kn - true_kn) ** 2)))

    # Drawn as scored, the estimates after the reset lie on the truth (0.05 kN measured);
    # on the sensor's clock they would lead it by half a second (5.4 kN).
    assert rms_error_kn(drawn.stamp_s[after], drawn.load_kn[after]) < 0.2
    assert rms_error_kn(on_sensor_clock.stamp_s[after], on_sensor_clock.load_kn[after]) > 2.0
    assert np.array_equal(drawn.stamp_s[: reset[0]], on_sensor_clock.stamp_s[: reset[0]])

    # A replay that stopped at 20 s is drawn over its 20 s, not over the truth's 60 s.
    early = _series(result.states[: reset[0] // 2], None)
    figure = _load_figure(early, truth, xlabel="t", title="stopped")
    _estimates_span(figure, early.stamp_s)
    assert all(axis.get_xlim()[1] < 21.0 for axis in figure.axes)
    # The reset is marked where it is drawn (nothing showed where the time line restarted).
    figure = _load_figure(drawn, truth, xlabel="t", title="sensor-faults")
    marks = [line for line in figure.axes[0].get_lines() if line.get_label() == "sensor time reset"]
    assert [line.get_xdata()[0] for line in marks] == [drawn.stamp_s[reset[0]]]


def test_cli_writes_report_and_metrics_and_exits_1_on_damage(
    bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scene_file = tmp_path / "scene.yaml"
    scene_file.write_text(json.dumps(SCENE))  # JSON is YAML
    report, metrics = tmp_path / "report", tmp_path / "metrics.json"
    argv = ["replay", str(bag), "--scene", str(scene_file)]
    code = main([*argv, "--report", str(report), "--metrics-json", str(metrics)])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "jammed rollers 1" in out and "load RMSE" in out
    assert sorted(p.name for p in report.iterdir()) == [
        "index.html",
        "jams.png",
        "load.png",
        "precision_loss.png",
    ]
    scores = json.loads(metrics.read_text())
    assert scores["jams"][0]["count"] == 1 and scores["false_jam_declarations"] == 0
    # The index page lists what the metrics JSON holds (it left out samples_read, partial).
    index = (report / "index.html").read_text()
    assert "&quot;samples_read&quot;: 12000" in index and "&quot;partial&quot;: null" in index

    damaged = tmp_path / "cut"
    shutil.copytree(bag, damaged)
    mcap = next(damaged.glob("*.mcap"))
    mcap.write_bytes(mcap.read_bytes()[:200_000])
    assert main(["replay", str(damaged), "--scene", str(scene_file)]) == 1
    assert "DAMAGED" in capsys.readouterr().out


def test_ctrl_c_ends_the_replay_with_what_was_read(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A SIGINT after the first chunk (20 s of sudden-jam): the output bag is closed complete,
    report and metrics cover the 20 s (the second jam, at 25 s, is not scored), exit 130. It
    was a KeyboardInterrupt traceback, an output bag without metadata.yaml and no report."""
    real = replay_command.replay

    def interrupted(*args: Any, progress: Callable[[int], None], **kwargs: Any) -> ReplayResult:
        def then_ctrl_c(samples: int) -> None:
            progress(samples)
            os.kill(os.getpid(), signal.SIGINT)

        return real(*args, progress=then_ctrl_c, **kwargs)

    monkeypatch.setattr(replay_command, "replay", interrupted)
    out, report, metrics = tmp_path / "out", tmp_path / "report", tmp_path / "m.json"
    argv = ["replay", str(BUNDLED_BAGS / "sudden-jam"), "--out", str(out)]
    code = main([*argv, "--report", str(report), "--metrics-json", str(metrics)])
    printed = capsys.readouterr().out
    assert code == 130, printed
    assert "STOPPED by Ctrl-C" in printed and f"wrote bag {out}, metrics {metrics}" in printed
    assert len(read_motor_samples(out, InputTopics())) == replay_module.CHUNK_SAMPLES
    assert (report / "index.html").is_file()
    scores = json.loads(metrics.read_text())
    assert [jam["count"] for jam in scores["jams"]] == [1]
    # The outputs say they cover part of the bag (they looked like those of a 20 s run).
    assert scores["partial"] == "stopped by Ctrl-C after 20000 samples"
    assert "(stopped by Ctrl-C after 20000 samples)" in (report / "index.html").read_text()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


@pytest.mark.parametrize("name", ["out", "out.mcap"])
def test_a_second_ctrl_c_aborts_and_removes_the_incomplete_output(
    name: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Two SIGINTs while the first chunk is written: it was a traceback and an output bag
    without metadata.yaml that made the rerun fail ("--out: ... exists"). The same for a
    bare MCAP file, and its working directory goes too."""
    real = replay_command.replay

    def aborted(*args: Any, progress: Callable[[int], None], **kwargs: Any) -> ReplayResult:
        def then_ctrl_c_twice(samples: int) -> None:
            progress(samples)
            os.kill(os.getpid(), signal.SIGINT)
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)  # the second one raises at the next bytecode

        return real(*args, progress=then_ctrl_c_twice, **kwargs)

    monkeypatch.setattr(replay_command, "replay", aborted)
    out = tmp_path / name
    argv = ["replay", str(BUNDLED_BAGS / "sudden-jam"), "--out", str(out)]
    assert main(argv) == 130
    assert capsys.readouterr().err.splitlines()[-2:] == [
        f"removed the incomplete {out}",
        "prsm-health: aborted by Ctrl-C",
    ]
    assert list(tmp_path.iterdir()) == []
    monkeypatch.setattr(replay_command, "replay", real)
    assert main(argv) == 0  # the rerun
    assert len(read_motor_samples(out, InputTopics())) == 60_000
    assert [p.name for p in tmp_path.iterdir()] == [name]


def test_cli_refuses_a_missing_bag_and_bad_params_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["replay", str(tmp_path / "nope")]) == 2
    assert "no such bag" in capsys.readouterr().err
    bad = tmp_path / "bad.yaml"
    bad.write_text("actuator: {preset: dong2022-downhole}\nfilter: {block_duration_s: -1}\n")
    assert main(["replay", str(tmp_path / "nope"), "--params", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--params: {bad}: filter.block_duration_s" in err
    # A hardware_id the node refuses (it names the state file) was written into --out.
    with pytest.raises(SystemExit) as exit_info:
        main(["replay", str(tmp_path / "nope"), "--hardware-id", "left arm"])
    assert exit_info.value.code == 2
    assert "--hardware-id: must match [A-Za-z0-9_.-]+, got 'left arm'" in capsys.readouterr().err


def test_cli_checks_output_paths_before_the_replay_and_makes_the_metrics_folder(
    bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    a_file = tmp_path / "a-file"
    a_file.write_text("")
    assert main(["replay", str(bag), "--report", str(a_file)]) == 2
    captured = capsys.readouterr()
    assert captured.out == "", "refused before replaying"
    assert "--report" in captured.err and captured.err.count("\n") == 1
    assert main(["replay", str(bag), "--metrics-json", str(tmp_path)]) == 2
    assert "is a directory" in capsys.readouterr().err
    assert main(["replay", str(bag), "--joint-name", "j1"]) == 2
    assert "--joint-states" in capsys.readouterr().err
    assert main(["replay", str(bag), "--effort", "torque"]) == 2
    assert "--effort: applies only with --joint-states" in capsys.readouterr().err
    # Checked before the replay too: these failed after it, with a traceback.
    same = tmp_path / "same"
    assert main(["replay", str(bag), "--out", str(same), "--metrics-json", str(same)]) == 2
    assert "overlaps --out" in capsys.readouterr().err
    assert main(["replay", str(bag), "--metrics-json", str(a_file / "metrics.json")]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and "--metrics-json: cannot make the folder" in captured.err

    # Nothing is written into the bag being replayed (a metrics file overwrote its .mcap).
    mcap = bag / f"{bag.name}.mcap"
    before = mcap.read_bytes()
    for option, path in (("--metrics-json", mcap), ("--report", bag / "report")):
        assert main(["replay", str(bag), option, str(path)]) == 2
        assert f"{option}: {path} is in the bag being replayed" in capsys.readouterr().err
    assert mcap.read_bytes() == before and not (bag / "report").exists()

    metrics = tmp_path / "new" / "folder" / "metrics.json"
    assert main(["replay", str(bag), "--metrics-json", str(metrics)]) == 0
    assert json.loads(metrics.read_text())["jams"]


@pytest.mark.parametrize(
    ("outer", "inner"),
    [("--out", "--report"), ("--report", "--out"), ("--report", "--metrics-json")],
)
def test_cli_refuses_an_output_inside_another(
    bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], outer: str, inner: str
) -> None:
    """Pins that an output inside another one's path is refused before the replay, whichever
    option names the outer one (the options are compared in a fixed order, so both nestings
    occur). A mutation review found the nesting unguarded: only equal paths were tested."""
    paths = {outer: tmp_path / "outer", inner: tmp_path / "outer" / "inner"}
    assert main(["replay", str(bag), *(str(v) for kv in paths.items() for v in kv)]) == 2
    captured = capsys.readouterr()
    assert captured.out == "", "refused before replaying"
    first, second = sorted(paths, key=["--out", "--report", "--metrics-json"].index)
    assert f"{second}: {paths[second]} overlaps {first} {paths[first]}" in captured.err


def test_cli_writes_the_report_into_an_existing_folder(
    bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Pins that --report takes a folder that exists (only a file there is refused). A
    mutation review found it unguarded (an existing report folder was refused)."""
    report = tmp_path / "report"
    report.mkdir()
    assert main(["replay", str(bag), "--report", str(report)]) == 0, capsys.readouterr().err
    assert (report / "index.html").is_file()


def test_cli_says_when_no_sample_matches_the_joint_name_and_what_is_skipped(
    bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["replay", str(bag), "--joint-states", "/joint_states", "--joint-name", "wrong"]
    out, report, metrics = tmp_path / "a" / "out.mcap", tmp_path / "r", tmp_path / "m" / "m.json"
    outputs = ["--out", str(out), "--report", str(report), "--metrics-json", str(metrics)]
    assert main([*argv, *outputs]) == 2
    captured = capsys.readouterr()
    assert "rejected" in captured.out  # the summary first
    assert "'wrong'" in captured.err and "'prsm_motor'" in captured.err
    assert "rejected as non_finite" in captured.err
    # The output of a failed replay is not left behind to block the rerun (found in review),
    # nor the folders made for the outputs.
    assert f"(the output bag {out} is not kept)" in captured.err
    assert sorted(tmp_path.iterdir()) == []
    # Refused options make no folder either (they did, before the option was checked).
    assert main(["replay", str(bag), "--joint-name", "j1", *outputs]) == 2
    assert "--joint-name: applies only" in capsys.readouterr().err
    assert sorted(tmp_path.iterdir()) == []

    no_truth = tmp_path / "no-truth"
    with BagWriter(no_truth) as writer:
        write_motor_states(writer, read_motor_samples(bag, InputTopics()))
    metrics = tmp_path / "metrics.json"
    assert main(["replay", str(no_truth), "--metrics-json", str(metrics)]) == 0
    assert "--metrics-json: not written" in capsys.readouterr().out
    assert not metrics.exists()


def test_a_bag_refused_in_the_middle_leaves_no_output_bag(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Its second file carries /motor_state as JointState: found after the output bag was
    begun, which stayed and blocked the rerun (found by a review session)."""
    first = write_bag(tmp_path / "a", motor=motor_samples(30_000, faults=False))
    with BagWriter(tmp_path / "b") as writer:
        write_joint_states(writer, motor_samples(3000, t0=30.0, faults=False), topic="/motor_state")
    split = split_bag(tmp_path / "split", [first, tmp_path / "b"])
    out = tmp_path / "out"
    assert main(["replay", str(split), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "topic /motor_state has two types" in err
    assert f"(the output bag {out} is not kept)" in err and not out.exists()


def test_cli_ends_with_an_error_when_the_input_topic_is_empty(
    bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The topic is declared but holds no message, the truth does: an error naming the topic
    (it ended with exit 0 and 'no ground truth to score')."""
    empty = tmp_path / "empty"
    with BagWriter(empty) as writer:
        writer.add_topic("/motor_state", MOTOR_STATE)
        write_truth(writer, read_truth(bag))
    assert main(["replay", str(empty), "--metrics-json", str(tmp_path / "m.json")]) == 2
    assert "no message on /motor_state" in capsys.readouterr().err


def test_cli_reports_damage_first_when_nothing_before_it_was_accepted(
    bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Cut before its first message: the damage's exit code (1), and what it left said."""
    damaged = tmp_path / "cut"
    shutil.copytree(bag, damaged)
    mcap = next(damaged.glob("*.mcap"))
    mcap.write_bytes(mcap.read_bytes()[:100])
    written, report = tmp_path / "outputs" / "out", tmp_path / "report"
    argv = ["replay", str(damaged), "--out", str(written), "--report", str(report)]
    assert main(argv) == 1
    out = capsys.readouterr().out
    assert "DAMAGED" in out and "(no estimate from what was read before it)" in out
    # Nothing is left to block the rerun (it kept an empty bag and folders, found in review).
    assert out.splitlines()[-1].endswith(f"(the output bag {written} is not kept)")
    assert not report.exists() and not written.parent.exists()


def test_a_truth_with_a_non_finite_value_is_scored_up_to_it(
    bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A NaN load in the truth: the bag is damaged there, the report and the metrics cover the
    truth before it (the report failed with matplotlib's 'Axis limits cannot be NaN or Inf')."""
    truth = read_truth(bag)
    load = truth.axial_load_n.copy()
    load[500] = math.nan
    broken = tmp_path / "broken-truth"
    with BagWriter(broken) as writer:
        write_motor_states(writer, read_motor_samples(bag, InputTopics()))
        write_truth(writer, dataclasses.replace(truth, axial_load_n=load))
    result = replay(broken, params())
    assert result.damage is not None and "message 500 holds a non-finite value" in str(
        result.damage
    )
    assert result.truth is not None and len(result.truth) == 500
    assert result.metrics is not None and math.isfinite(result.metrics.load_rmse_n)
    report, metrics = tmp_path / "report", tmp_path / "metrics.json"
    argv = ["replay", str(broken), "--scene", "sudden-jam", "--report", str(report)]
    assert main([*argv, "--metrics-json", str(metrics)]) == 1
    assert "DAMAGED" in capsys.readouterr().out and (report / "load.png").is_file()
    # Every input sample was read: the outputs say the truth is what was cut (they said "up
    # to the damage after 12000 samples"; found by a review session).
    partial = f"the truth up to its damage (all {result.samples} samples read)"
    assert result.inputs_complete and json.loads(metrics.read_text())["partial"] == partial
    # Cut before the first estimate: nothing to score, and still a damaged bag's report (the
    # scoring raised "no estimate within the truth's span": exit 2, no summary).
    load[1] = math.nan
    early = tmp_path / "early-nan"
    with BagWriter(early) as writer:
        write_motor_states(writer, read_motor_samples(bag, InputTopics()))
        write_truth(writer, dataclasses.replace(truth, axial_load_n=load))
    assert main(["replay", str(early), "--scene", "sudden-jam"]) == 1
    out = capsys.readouterr().out
    assert "DAMAGED" in out and "estimates lie outside the truth's span\n" in out


def test_a_truth_whose_stamps_go_back_is_scored_up_to_them(bag: Path, tmp_path: Path) -> None:
    """Truth stamps that went back 2 s were looked up as they came: a load RMSE of 17.7 %
    where the right truth gives 0.8 %, exit 0 (found by a review session)."""
    truth = read_truth(bag)
    stamps = truth.stamp_s.copy()
    stamps[600:] -= 2.0
    load = truth.axial_load_n.copy()
    load[700] = math.nan  # later: the earlier damage is the one named (it named this one)
    broken = tmp_path / "truth-back"
    with BagWriter(broken) as writer:
        write_motor_states(writer, read_motor_samples(bag, InputTopics()))
        write_truth(writer, dataclasses.replace(truth, stamp_s=stamps, axial_load_n=load))
    result = replay(broken, params())
    assert result.damage is not None
    assert f"message 600 is stamped {stamps[600]:.9g} s, not after the one before it" in str(
        result.damage
    )
    assert result.truth is not None and len(result.truth) == 600
    intact = replay(bag, params())
    assert result.metrics is not None and intact.metrics is not None
    assert result.metrics.load_rmse_n < 2.0 * intact.metrics.load_rmse_n


def test_a_truth_stamp_equal_to_the_one_before_is_damage(bag: Path, tmp_path: Path) -> None:
    """Truth stamps must advance: message 600 stamped as message 599 is damage there, and
    the truth is scored up to it (600 of its 1200 messages). A mutation review found this
    unguarded: with a repeated stamp taken as advancing, there was no damage and all 1200
    were kept."""
    truth = read_truth(bag)
    assert len(truth) == 1200
    stamps = truth.stamp_s.copy()
    stamps[600] = stamps[599]
    repeated = tmp_path / "truth-repeated"
    with BagWriter(repeated) as writer:
        write_motor_states(writer, read_motor_samples(bag, InputTopics()))
        write_truth(writer, dataclasses.replace(truth, stamp_s=stamps))
    result = replay(repeated, params())
    assert result.damage is not None
    expected = (
        f"{TRUTH_TOPIC}: message 600 is stamped {stamps[600]:.9g} s, not after the one "
        f"before it ({stamps[599]:.9g} s)"
    )
    assert expected in str(result.damage)
    assert result.truth is not None and len(result.truth) == 600


def test_metrics_that_cannot_be_computed_are_null_in_the_json(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """0.3 s at standstill: no estimate in motion, so no load RMSE or NEES. JSON has no NaN
    (json.dumps wrote a bare NaN, which strict parsers refuse)."""
    short = tmp_path / "short"
    record(Simulator(scene_from_mapping({**SCENE, "duration_s": 0.3, "jams": []})), short)
    metrics = tmp_path / "metrics.json"
    assert main(["replay", str(short), "--metrics-json", str(metrics)]) == 0
    out = capsys.readouterr().out
    assert "vs truth: no load estimate in motion to score" in out
    # Printed as "identified after -" and "precision loss error nan %".
    assert (
        "jams: none, false declarations 0, count right in 100.00 % of the estimates; no "
        "precision loss in the truth to compare"
    ) in out

    def refuse(constant: str) -> None:
        raise ValueError(f"not JSON: {constant}")

    scores = json.loads(metrics.read_text(), parse_constant=refuse)
    assert scores["load_rmse_n"] is None and scores["load_nees_mean"] is None
    assert scores["load_nees_consistent"] is None  # not tested, not failed (it read false)
    assert scores["load_nees_interval"] is None  # it read [null, null]


def test_params_with_another_block_size_still_replay(bag: Path) -> None:
    p = params()
    fine = dataclasses.replace(p, filter=dataclasses.replace(p.filter, block_duration_s=0.02))
    result = replay(bag, fine)
    assert result.metrics is not None and result.metrics.load_rmse_percent_rated < 2.0


def test_the_precision_loss_band_is_cut_at_zero() -> None:
    """A +-2 std band below zero would show a negative precision loss; the load's may."""
    figure, axis = plt.subplots()
    t, mean, std = np.array([0.0, 1.0]), np.array([1.0, 2.0]), np.array([1.0, 0.5])
    _band(axis, t, mean, std, "loss", non_negative=True)
    _band(axis, t, -mean, std, "load")
    loss, load = (c.get_paths()[0].vertices[:, 1] for c in axis.collections)
    labels = axis.get_legend_handles_labels()[1]
    plt.close(figure)
    assert loss.min() == 0.0 and loss.max() == 3.0  # -1 uncut
    assert load.min() == -3.0
    assert labels == ["loss +-2 std, cut at 0", "loss", "load +-2 std", "load"]


def test_diagnostics_go_on_after_the_clock_jumps_back(bag: Path, tmp_path: Path) -> None:
    """The clock jumps back by 5 s halfway (the log times keep the arrival order): the
    estimator follows the new time line after filter.time_reset_after_s, and /diagnostics
    goes on about once per second of it instead of waiting until the old schedule's time."""
    motor = read_motor_samples(bag, InputTopics())
    half = len(motor) // 2
    stamps = motor.stamp_s.copy()
    stamps[half:] -= 5.0
    jumped = tmp_path / "jumped"
    arrival = 1_700_000_000_000_000_000 + np.arange(len(motor), dtype=np.int64) * 1_000_000
    with BagWriter(jumped) as writer:
        write_motor_states(
            writer,
            MotorSamples(stamps, motor.current_a, motor.speed_rad_s, motor.position_rad),
            receive_time_ns=arrival,
        )
    out = tmp_path / "out"
    result = replay(jumped, params(), out=out)
    assert result.counters.time_resets == 1
    with (out / "out.mcap").open("rb") as stream:  # in the order written, not sorted
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        seconds = [
            decoded.header.stamp.sec + 1e-9 * decoded.header.stamp.nanosec
            for _, channel, _, decoded in reader.iter_decoded_messages(log_time_order=False)
            if channel.topic == DIAGNOSTICS_TOPIC
        ]
    jumps = np.flatnonzero(np.diff(seconds) < 0.0) + 1
    assert len(jumps) == 1, f"diagnostics written on one time line only: {seconds}"
    jump = int(jumps[0])
    # Before the fix none came on the new time line until the old schedule's next second
    # (7 s, the line's end): now they go on from the time reset (the first 0.1 s rejected).
    new_line = np.array(seconds[jump:])
    assert len(new_line) >= 4 and new_line[0] < stamps[half] + 1.2
    # Once per second of the new line, and at the end (the last input's stamp).
    spacing = np.diff(new_line[:-1])
    assert np.all((spacing > 0.9) & (spacing < 1.1)), new_line
    assert new_line[-1] == pytest.approx(stamps[-1])


def test_the_last_diagnostics_are_not_written_twice(bag: Path, tmp_path: Path) -> None:
    """2,495 samples of the scene in motion (from its second 1), restamped exactly 1 ms
    apart: pieces of 499 samples, an estimate from the first, the diagnostics due at the
    last piece, which writes them at the last input's stamp; the end (the inputs' clock not
    moved since) does not write them again, so the /diagnostics stamps strictly increase.
    A mutation review found this unguarded: written at the end even when the clock had not
    moved since the last, the last stamp came twice (0.498, 1.496, 2.494, 2.494)."""
    motor = read_motor_samples(bag, InputTopics())[1000:3495]
    exact = MotorSamples(
        1e-3 * np.arange(2495), motor.current_a, motor.speed_rad_s, motor.position_rad
    )
    short = tmp_path / "short"
    with BagWriter(short) as writer:
        write_motor_states(writer, exact)
    out = tmp_path / "out"
    result = replay(short, params(), out=out)
    assert result.samples == 2495
    store = typestore()
    with Reader(out) as reader:
        seconds = [
            (message := store.deserialize_cdr(raw, c.msgtype)).header.stamp.sec
            + 1e-9 * message.header.stamp.nanosec
            for c, _, raw in reader.messages()
            if c.topic == DIAGNOSTICS_TOPIC
        ]
    assert np.all(np.diff(seconds) > 0.0), seconds
    # Once per second from the first piece's end, the last at the last piece's end.
    assert seconds == pytest.approx([0.498, 1.496, 2.494], abs=1e-9)


def test_the_report_of_a_bag_without_truth_says_it_has_no_metrics(tmp_path: Path) -> None:
    """Pins the index page of a report without truth: the three plots and a line saying the
    bag has no ground truth, so no metrics (not an empty section). A mutation review found it
    unguarded."""
    states = [state(stamp_s=t) for t in (1.0, 2.0, 3.0)]
    files = write_report(tmp_path / "report", states, None, None, title="field run")
    assert [f.name for f in files] == [*PLOTS, "index.html"]
    index = files[-1].read_text()
    assert (
        "<h2>Metrics</h2>\n<p>The bag has no ground truth (/truth/state): no metrics.</p>" in index
    )


def test_the_load_plot_shows_the_error_inside_its_band_when_there_is_truth(bag: Path) -> None:
    """With the truth, load.png has a second panel: estimate minus truth (as scored) and the
    +-2 std band about zero, its legend above it (inside, it covered the data); without, one
    panel. The load's axis spans the estimate and the truth, cutting off the band (tens of kN
    at the stroke ends), and the estimate's line is drawn over the wider, paler truth."""
    result = replay(bag, params())
    assert result.truth is not None
    series = _series(result.states, None)
    with_truth = _load_figure(series, result.truth, xlabel="t", title="x")
    without = _load_figure(series, None, xlabel="t", title="x")
    try:
        assert len(without.axes) == 1
        error_axis = with_truth.axes[1]
        (line,) = error_axis.lines
        true_kn = np.interp(series.stamp_s, result.truth.stamp_s, result.truth.axial_load_n / 1e3)
        np.testing.assert_allclose(line.get_ydata(), series.load_kn - true_kn)
        # Scaled to the motion: the errors while moving fill the axis (not the standstill's
        # band of tens of kN).
        low, high = error_axis.get_ylim()
        moving = series.moving
        size = np.abs(series.load_kn - true_kn)[moving]
        assert high == -low and np.quantile(size, 0.99) < high <= 2 * np.quantile(size, 0.99)
        assert high < 0.5 * 2 * series.load_std_kn.max()
        with_truth.canvas.draw()
        legend = error_axis.get_legend()
        assert legend is not None
        assert legend.get_window_extent().y0 >= error_axis.get_window_extent().y1 - 1.0
        load_axis = with_truth.axes[0]
        true_load_kn = result.truth.axial_load_n / 1e3
        shown = np.concatenate([series.load_kn, true_load_kn])
        low, high = load_axis.get_ylim()
        margin = 0.1 * (shown.max() - shown.min())
        assert (low, high) == pytest.approx((shown.min() - margin, shown.max() + margin))
        wide = _load_figure(
            dataclasses.replace(series, load_std_kn=100.0 * series.load_std_kn),
            result.truth,
            xlabel="t",
            title="x",
        )
        assert wide.axes[0].get_ylim() == (low, high)  # a wider band is cut off
        plt.close(wide)
        estimate, truth = load_axis.lines
        assert truth.get_zorder() < estimate.get_zorder()
        assert truth.get_linewidth() > estimate.get_linewidth()
        assert truth.get_linestyle() == "--"
        assert without.axes[0].get_ylim() == pytest.approx(
            (
                series.load_kn.min() - 0.1 * np.ptp(series.load_kn),
                series.load_kn.max() + 0.1 * np.ptp(series.load_kn),
            )
        )
    finally:
        plt.close(with_truth)
        plt.close(without)


def test_the_diagnostics_of_a_slow_input_say_its_rate(tmp_path: Path) -> None:
    """A 50 Hz bag: the replay counted the inputs per piece of 1000 samples (20 s here) at
    the latest estimate, so its /diagnostics said "1000 Hz" (OK against 100 Hz) three times
    in 60 s. The inputs now count over the time their samples cover and the diagnostics come
    once per second of the inputs' clock (the latest accepted stamp), the last one at the
    end."""
    slow = tmp_path / "slow"
    scene = {**SCENE, "rate_hz": 50.0, "truth_rate_hz": 50.0, "joint_states": False}
    record(Simulator(scene_from_mapping(scene)), slow)
    out = tmp_path / "out"
    result = replay(slow, params(), out=out)
    store = typestore()
    with Reader(out) as reader:
        arrays = [
            store.deserialize_cdr(raw, c.msgtype)
            for c, _, raw in reader.messages()
            if c.topic == DIAGNOSTICS_TOPIC
        ]
    stamps = [a.header.stamp.sec + 1e-9 * a.header.stamp.nanosec for a in arrays]
    assert 11 <= len(arrays) <= 14, stamps  # once per second of the 12 s bag, and the end
    assert np.all((np.diff(stamps[:-1]) > 0.9) & (np.diff(stamps[:-1]) < 1.1)), stamps
    motor = read_motor_samples(slow, InputTopics())
    assert stamps[-1] == pytest.approx(motor.stamp_s[-1])
    inputs = [
        {kv.key: kv.value for kv in status.values}
        for array in arrays
        for status in array.status
        if status.name.endswith("input health")
    ]
    levels = [
        status.level
        for array in arrays
        for status in array.status
        if status.name.endswith("input health")
    ]
    # After the first second (a window not yet full) every one says 50 Hz, a WARN.
    assert all(float(values["rate_hz"]) == pytest.approx(50.0, abs=2.0) for values in inputs[2:])
    assert set(levels[2:]) == {1}
    assert int(inputs[-1]["received"]) == len(motor) == result.samples


def test_a_reader_that_leaves_early_does_not_cost_the_outputs(
    bag: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``prsm-health replay ... | head -2``: the summary was printed before the metrics and
    the report were written, so a reader gone before it (exit 141) left neither, and the
    output bag, already written, blocked the rerun."""

    class GoneReader:
        def write(self, text: str) -> int:
            raise BrokenPipeError(32, "Broken pipe")

        def flush(self) -> None:
            pass

    report, metrics = tmp_path / "report", tmp_path / "metrics.json"
    argv = ["replay", str(bag), "--report", str(report), "--metrics-json", str(metrics)]
    parser = argparse.ArgumentParser()
    replay_command.add_replay_command(parser.add_subparsers())
    args = parser.parse_args(argv)
    monkeypatch.setattr("sys.stdout", GoneReader())
    with pytest.raises(BrokenPipeError):
        replay_command.run_replay(args)
    assert json.loads(metrics.read_text())["estimates"] > 0
    assert (report / "index.html").is_file()


def test_an_output_that_fails_to_write_still_gets_the_summary_printed(
    bag: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The outputs are written before the summary; one that fails (a disk full after the
    checks) must not take the summary with it."""

    def full_disk(*_: Any, **__: Any) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr("prsm_health.report.write_report", full_disk)
    code = main(["replay", str(bag), "--report", str(tmp_path / "report")])
    captured = capsys.readouterr()
    assert code == 2 and "--report: cannot write into" in captured.err
    assert "samples accepted 12000" in captured.out
    assert re.search(
        r"gaps 0; current noise 0\.0\d\d A\n  inputs in motion: speed noise 0\.\d\d rad/s; "
        r"position per speed (0\.99|1\.00); "
        r"torque along the motion \+\d\.\d\d N·m forward, \+\d\.\d\d N·m reverse\n",
        captured.out,
    )


def test_the_summary_says_what_was_not_measured_and_inputs_that_disagree(
    bag: Path,
) -> None:
    result = replay(bag, params())
    unmeasured = dataclasses.replace(result, measures=InputMeasures())
    text = replay_command.summary(bag, "x", unmeasured)
    assert "gaps 0; current noise not measured (no block of 12 samples)\n" in text
    assert (
        "  inputs in motion: speed noise not measured (under 64 blocks in motion); position and "
        "speed not compared (under 64 blocks in motion); torque along the motion not measured "
        "forward, not measured reverse\n"
    ) in text
    wrong = replay_command.summary(
        bag, "x", dataclasses.replace(result, measures=InputMeasures(position_per_speed=0.2))
    )
    assert "; WRONG INPUT: the position moves 0.2 rad per rad the speed says (a unit" in wrong
    # A current of the other sign (motion_torque.py); a load that keeps its direction brakes
    # one way only.
    braking = replay_command.summary(
        bag,
        "x",
        dataclasses.replace(result, measures=InputMeasures(torque_along_motion_nm=(-5.0, -7.0))),
    )
    assert (
        "; WRONG INPUT: the motor brakes the motion both ways (-5.00 N·m along it forward, "
        "-7.00 N·m reverse): a current of the other sign"
    ) in braking
    weight = replay_command.summary(
        bag,
        "x",
        dataclasses.replace(result, measures=InputMeasures(torque_along_motion_nm=(2.0, -1.5))),
    )
    assert "; torque along the motion +2.00 N·m forward, -1.50 N·m reverse\n" in weight


def test_the_summary_names_the_rejections_by_reason_and_field(bag: Path) -> None:
    """A speed in rpm read as rad/s: half of it beyond three times the largest speed. The
    summary said only "rejected 30476"."""
    result = replay(bag, params())
    counters = dataclasses.replace(result.counters, rejected=[2, 30, 0, 1, 0])
    rejected = dataclasses.replace(
        result,
        counters=counters,
        measures=InputMeasures(
            out_of_range_by_field={"stamp": 0, "current": 0, "speed": 30, "position": 0}
        ),
    )
    text = replay_command.summary(bag, "x", rejected)
    assert ", rejected 33 (non_finite 2, out_of_range: speed 30, spike 1); time resets" in text
    assert ", rejected 0; time resets 0, gaps 0; current noise" in replay_command.summary(
        bag, "x", result
    )


def test_the_summary_says_how_often_the_count_was_right(bag: Path) -> None:
    """From the jam count's calibration bins: the share of estimates whose most likely count
    was the true one, and the largest probability a wrong one had (its bin's lower edge)."""
    result = replay(bag, params())
    assert result.metrics is not None
    bins = [
        CalibrationBin(0.5, 0.9, 10, 9, 0.7),
        CalibrationBin(0.99, 0.999, 20, 15, 0.995),
        CalibrationBin(0.99999, 1.0, 70, 70, 1.0),
    ]
    metrics = dataclasses.replace(result.metrics, jam_calibration=tuple(bins))
    text = replay_command.summary(bag, "x", dataclasses.replace(result, metrics=metrics))
    assert ", count right in 94.00 % of the estimates (wrong ones at p >= 0.99); " in text
    none = dataclasses.replace(result.metrics, jam_calibration=())
    text = replay_command.summary(bag, "x", dataclasses.replace(result, metrics=none))
    assert ", no count scored; " in text


def test_the_time_label_names_each_clock_jumps_shift_once() -> None:
    """The plots' x label names the shift of the estimates after each sensor clock jump (the
    metrics' offsets, one per time line), not the same offset again after a gap, and nothing
    without a jump."""
    assert _time_label(None) == "time [s]"
    assert _time_label((0.0,)) == "time [s]"
    assert _time_label((0.0, 0.0)) == "time [s]"  # a gap: the same clock
    shifted = "time [s] (estimates after a sensor clock jump shifted by {}, as scored)"
    assert _time_label((0.0, 5.0, 5.0)) == shifted.format("+5.000 s")
    assert _time_label((2.0,)) == shifted.format("+2.000 s")  # jumped before the first
    assert _time_label((0.0, 5.0, -3.25)) == shifted.format("+5.000 s, -3.250 s")


def test_the_jam_plot_names_only_the_counts_that_were_ever_likely() -> None:
    """Eleven legend entries would hide the plot: a count is shown where its probability
    exceeded SHOWN_PROBABILITY somewhere, and only then."""
    probabilities = np.zeros((4, 11))
    probabilities[:, 0] = [1.0, 0.5, 0.0, 0.0]
    probabilities[:, 1] = [0.0, 0.5, 1.0 - SHOWN_PROBABILITY, 0.0]
    probabilities[2, 2] = SHOWN_PROBABILITY  # never above it
    probabilities[3, 3] = 1.0
    assert _counts_shown(probabilities) == [0, 1, 3]
