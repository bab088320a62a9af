"""The bundled bags: both readers decode them, they are small, and their scenes regenerate them."""

from __future__ import annotations

import shutil
import signal
import subprocess
import sys
import time
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

from prsm_health.bags.errors import BagError
from prsm_health.bags.reader import InputTopics, read_motor_samples, read_truth
from prsm_health.bags.typestore import typestore
from prsm_health.cli import main
from prsm_health.scenes.scene import load_scene, scene_names

BAGS = Path(__file__).resolve().parents[2] / "bags"
TOPICS = {
    "/motor_state": "prsm_health_msgs/msg/MotorState",
    "/truth/state": "prsm_health_msgs/msg/GroundTruth",
}
MAX_BYTES = 3 * 1024 * 1024


def test_every_bundled_scene_has_its_bag_and_a_readme_section() -> None:
    readme = (BAGS / "README.md").read_text(encoding="utf-8")
    assert sorted(p.name for p in BAGS.iterdir() if p.is_dir()) == list(scene_names())
    for name in scene_names():
        assert f"## {name}\n" in readme
        assert f"prsm-health simulate --scene {name} --out bags/{name} --force" in readme


@pytest.mark.parametrize("name", scene_names())
def test_bundled_bag_decodes_with_rosbags_and_mcap(name: str) -> None:
    bag = BAGS / name
    assert sum(f.stat().st_size for f in bag.iterdir()) <= MAX_BYTES
    scene = load_scene(name)
    samples = read_motor_samples(bag)
    truth = read_truth(bag)
    dropped = sum(round(d.duration_s * scene.rate_hz) for d in scene.sensor_faults.dropouts)
    assert len(samples) == scene.samples - dropped
    assert len(truth) == scene.samples // scene.truth_decimation
    assert np.all(np.diff(truth.jammed_rollers) >= 0)
    assert np.all(np.diff(truth.precision_loss_m) >= 0.0)

    with AnyReader([bag], default_typestore=typestore()) as reader:
        assert {c.topic: c.msgtype for c in reader.connections} == TOPICS
        current = [
            reader.deserialize(raw, c.msgtype).current_a
            for c, _, raw in reader.messages()
            if c.topic == "/motor_state"
        ]
    np.testing.assert_array_equal(np.array(current), samples.current_a)

    loads = []
    with (bag / f"{name}.mcap").open("rb") as stream:
        mcap = make_reader(stream, decoder_factories=[DecoderFactory()])
        for schema, channel, _, message in mcap.iter_decoded_messages():
            assert (schema.name, schema.encoding) == (TOPICS[channel.topic], "ros2msg")
            if channel.topic == "/truth/state":
                loads.append(message.axial_load_n)
    np.testing.assert_array_equal(np.array(loads), truth.axial_load_n)


#: Relative difference allowed between a ground-truth value regenerated on another CPU and
#: the bundled one: numpy chooses its SIMD kernels for pow, exp, sin, ... at run time, and
#: they differ in the last bits between CPUs (measured on an AVX2-only machine against the
#: bags written on the earlier CI machines: friction, precision loss and fatigue damage of
#: stationary-hold differ by at most 6.6e-15 relative, every other field is identical).
TRUTH_RTOL = 1e-12


def test_a_bundled_bag_is_what_its_scene_regenerates(tmp_path: Path) -> None:
    """The same metadata, the same motor samples bit for bit (the sensors quantise them),
    and the same ground truth to the last bits of the CPU's floating point. (On one machine
    the whole .mcap regenerates byte for byte: test_writer and ``make bags-check``.)"""
    name = "stationary-hold"
    out = tmp_path / name
    assert main(["simulate", "--scene", name, "--out", str(out)]) == 0
    assert (out / "metadata.yaml").read_bytes() == (BAGS / name / "metadata.yaml").read_bytes()
    regenerated, bundled = (read_motor_samples(b, InputTopics()) for b in (out, BAGS / name))
    for field in fields(bundled):
        np.testing.assert_array_equal(
            getattr(regenerated, field.name), getattr(bundled, field.name), field.name
        )
    regenerated_truth, bundled_truth = read_truth(out), read_truth(BAGS / name)
    assert regenerated_truth is not None and bundled_truth is not None
    for field in fields(bundled_truth):
        np.testing.assert_allclose(
            getattr(regenerated_truth, field.name),
            getattr(bundled_truth, field.name),
            rtol=TRUTH_RTOL,
            atol=0.0,
            err_msg=field.name,
        )


def test_simulate_writes_joint_states_and_refuses_to_overwrite(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "short"
    argv = ["simulate", "--scene", "nominal-downhole", "--duration", "3", "--out", str(out)]
    assert main([*argv, "--joint-states", "--seed", "9"]) == 0
    motor = read_motor_samples(out)
    joints = read_motor_samples(out, InputTopics(joint_states="/joint_states"))
    assert len(motor) == 3000
    for field in ("current_a", "speed_rad_s", "position_rad"):
        np.testing.assert_array_equal(getattr(joints, field), getattr(motor, field))
    capsys.readouterr()
    assert main(argv) == 2
    assert f"{out} exists" in capsys.readouterr().err
    assert main([*argv, "--force"]) == 0
    assert len(read_motor_samples(out)) == 3000
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "keep.txt").write_text("mine", encoding="utf-8")
    assert (
        main(
            [
                "simulate",
                "--scene",
                "nominal-downhole",
                "--duration",
                "1",
                "--force",
                "--out",
                str(tmp_path / "notes"),
            ]
        )
        == 2
    )
    assert "not a bag directory" in capsys.readouterr().err
    assert (tmp_path / "notes" / "keep.txt").exists()
    # A bare MCAP file (docs/bags.md), replaced with --force like a bag directory.
    bare = tmp_path / "short.mcap"
    argv = ["simulate", "--scene", "nominal-downhole", "--duration", "1", "--out", str(bare)]
    assert main(argv) == 0 and bare.is_file()
    assert main(argv) == 2
    assert main([*argv[:-3], "2", "--out", str(bare), "--force"]) == 0
    assert len(read_motor_samples(bare)) == 2000
    # --force removes bags only: not a file that is no MCAP, not what a link points to (the
    # bag behind a link was deleted, then the link's rmdir failed with a traceback).
    capsys.readouterr()
    notes = tmp_path / "notes.mcap"
    notes.write_text("mine", encoding="utf-8")
    assert main([*argv[:-1], str(notes), "--force"]) == 2
    assert "notes.mcap is not an MCAP file (not removed)" in capsys.readouterr().err
    assert notes.read_text(encoding="utf-8") == "mine"
    for name, target in (("link", out), ("link.mcap", bare)):
        (tmp_path / name).symlink_to(target)
        assert main([*argv[:-1], str(tmp_path / name), "--force"]) == 2
        assert "is a symbolic link, not a bag (not removed)" in capsys.readouterr().err
    assert len(read_motor_samples(out)) == 3000 and len(read_motor_samples(bare)) == 2000
    # What a killed write of a bare file leaves: refused, then removed with --force.
    killed = tmp_path / ".short.mcap.writing" / "short"
    killed.mkdir(parents=True)
    bare.replace(killed / "short.mcap")
    assert main(argv) == 2
    assert ".short.mcap.writing is left from a write that was killed" in capsys.readouterr().err
    assert main([*argv, "--force"]) == 0
    assert not killed.parent.exists() and len(read_motor_samples(bare)) == 1000


def test_simulate_reports_a_bad_scene_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scene = tmp_path / "bad.yaml"
    scene.write_text(
        "name: bad\nactuator: {preset: dong2022-downhole}\nduration_s: -1\n"
        "profile: {type: constant}\n",
        encoding="utf-8",
    )
    assert main(["simulate", "--scene", str(scene), "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{scene}: duration_s" in err
    assert not (tmp_path / "b").exists()


def test_a_truncated_bag_is_refused_naming_the_file(tmp_path: Path) -> None:
    bag = tmp_path / "sudden-jam"
    shutil.copytree(BAGS / "sudden-jam", bag)
    mcap = bag / "sudden-jam.mcap"
    mcap.write_bytes(mcap.read_bytes()[: mcap.stat().st_size // 2])
    with pytest.raises(BagError, match=str(mcap)):
        read_truth(bag)


def test_simulate_at_a_low_rate_lowers_the_truth_rate(tmp_path: Path) -> None:
    """--rate 10 with the scenes' 100 Hz truth: the truth follows at 10 Hz (it was an error
    about truth_rate_hz, a setting the command line does not show); 150 Hz gives 75 Hz."""
    for rate, truth_hz in ((10, 10), (150, 75)):
        out = tmp_path / f"rate-{rate}"
        argv = ["simulate", "--scene", "nominal-downhole", "--duration", "2", "--rate", str(rate)]
        assert main([*argv, "--out", str(out)]) == 0
        assert len(read_motor_samples(out)) == 2 * rate
        assert len(read_truth(out)) == 2 * truth_hz


def test_simulate_says_which_jams_a_shortened_run_leaves_out(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """sudden-jam's jams at 4.5 s and 25 s: a 10 s run has the first only, and says so (a
    --duration or a scene file that put a jam beyond the end left it out without a word)."""
    err, jammed = simulate_sudden_jam(tmp_path, capsys, "10")
    assert err.endswith(
        "note: the jam(s) at 25 s come after the end of the run (10 s): not simulated\n"
    )
    assert jammed == 1


def test_a_jam_at_the_end_of_the_run_is_left_out_and_named(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Pins that a jam at the run's very end counts as after it: a 4.5 s run has its last
    sample before sudden-jam's jam at 4.5 s, so neither jam is simulated, and the note names
    both. A mutation review found it unguarded ('>' left the 4.5 s jam out without a word)."""
    err, jammed = simulate_sudden_jam(tmp_path, capsys, "4.5")
    assert err.endswith(
        "note: the jam(s) at 4.5 s, 25 s come after the end of the run (4.5 s): not simulated\n"
    )
    assert jammed == 0


def simulate_sudden_jam(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], duration: str
) -> tuple[str, int]:
    """sudden-jam (jams at 4.5 s and 25 s) simulated at 100 Hz for ``duration`` seconds: what
    it wrote on stderr, and the most rollers its truth shows jammed."""
    argv = ["simulate", "--scene", "sudden-jam", "--duration", duration, "--rate", "100"]
    assert main([*argv, "--out", str(tmp_path / "short")]) == 0
    truth = read_truth(tmp_path / "short")
    assert truth is not None
    return capsys.readouterr().err, int(truth.jammed_rollers.max())


def test_ctrl_c_during_simulate_leaves_a_complete_shorter_bag(tmp_path: Path) -> None:
    """SIGINT to a real ``prsm-health simulate`` process: it stops after the chunk being
    written, closes the bag (metadata.yaml, a readable MCAP) and exits 130 without a traceback."""
    out = tmp_path / "stopped"
    argv = ["simulate", "--scene", "nominal-downhole", "--duration", "3600", "--out", str(out)]
    process = subprocess.Popen(
        [sys.executable, "-m", "prsm_health.cli", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    deadline = time.monotonic() + 60.0
    while not any(out.glob("*.mcap")) and time.monotonic() < deadline:
        time.sleep(0.1)
    time.sleep(0.5)  # a few chunks in
    process.send_signal(signal.SIGINT)
    stdout, stderr = process.communicate(timeout=60)
    assert process.returncode == 130, stderr.decode()
    assert b"Traceback" not in stderr
    assert b"interrupted: the bag holds the first" in stdout
    assert (out / "metadata.yaml").exists()
    motor = read_motor_samples(out)
    assert 0 < len(motor) < 3_600_000
    assert len(read_truth(out)) == len(motor) // 10


def test_simulate_refuses_a_bag_larger_than_the_free_disk(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--duration 1e9 (a typo for 1e3?) would need about 50 TB: refused at once, nothing
    written (it ran silently, filling the disk)."""
    out = tmp_path / "huge"
    argv = ["simulate", "--scene", "nominal-downhole", "--duration", "1e9", "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "GB are free: shorten --duration" in err and err.count("\n") == 1
    assert not out.exists()
