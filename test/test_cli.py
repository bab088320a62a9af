"""The ``prsm-health`` command line: ``model``'s JSON and table, help texts, one-line errors,
and the exit codes of ``play`` and ``monitor`` (real processes, DDS isolated by conftest)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from prsm_health.cli import main
from test.ros.data import synthetic_run, write_bag


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_model_json_has_the_documented_fields(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(
        capsys,
        "model",
        "--preset",
        "meng2022-misalignment",
        "--axial-load",
        "50000",
        "--speed-rpm",
        "300",
        "--misalignment-arcmin",
        "1",
        "0",
        "--json",
    )
    assert code == 0
    doc = json.loads(out)
    forces = doc["contact_force_screw_roller_n"]
    assert len(forces) == 10 and len(forces[0]) == 20
    assert len(doc["contact_force_roller_nut_n"][9]) == 20
    assert len(doc["axial_clearance_mm"]) == 10
    for key in ("friction_torque_nm", "efficiency", "precision_loss_rate_um_per_h"):
        assert doc[key] > 0.0
    assert 0.0 < doc["efficiency"] < 1.0
    assert doc["fatigue_life_h"] > 0.0
    assert doc["inputs"]["axial_load"] == 50000.0
    assert doc["inputs"]["misalignment_arcmin"] == [1.0, 0.0]
    assert doc["inputs"]["wear_model"] == "archard"  # the preset's law (it echoed null)
    # Misalignment makes clearances differ along the roller (004 Fig. 8).
    clearances = doc["axial_clearance_mm"][0]
    assert max(clearances) - min(clearances) > 1e-3


def test_model_table_is_readable(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(
        capsys,
        "model",
        "--preset",
        "dong2022-downhole",
        "--axial-load",
        "20000",
        "--radial-load",
        "4000",
        "--case",
        "2",
    )
    assert code == 0
    assert "friction torque" in out and "case 2" in out
    assert len(out.splitlines()) == 7 + 10


def test_model_table_at_standstill_has_no_fatigue_life(capsys: pytest.CaptureFixture[str]) -> None:
    """Pins the table's fatigue life at 0 rpm: none, as nothing rolls over (not "inf h"). A
    mutation review found it unguarded."""
    code, out, _ = run(
        capsys,
        "model",
        "--preset",
        "dong2022-downhole",
        "--axial-load",
        "20000",
        "--speed-rpm",
        "0",
    )
    assert code == 0
    assert "  fatigue life                      - (no rotation)" in out.splitlines()


@pytest.mark.parametrize(
    "argv",
    [
        ["model", "--preset", "nope", "--axial-load", "1"],
        ["model", "--preset", "li2020-jamming", "--axial-load", "nan"],
        ["model", "--preset", "li2020-jamming", "--axial-load", "-5"],
        ["model", "--preset", "li2020-jamming", "--axial-load", "100", "--jammed", "11"],
        ["model", "--preset", "li2020-jamming", "--axial-load", "100", "--case", "3"],
        ["model", "--preset", "li2020-jamming", "--axial-load", "100", "--radial-load", "500"],
    ],
)
def test_invalid_arguments_give_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], argv: list[str]
) -> None:
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's own errors
        code = int(exc.code or 0)
    _, err = capsys.readouterr()
    assert code == 2
    assert len(err.strip().splitlines()) == 1
    assert err.startswith("prsm-health")


@pytest.mark.parametrize(
    ("argv", "error"),
    [
        (["model", "--axial-load", "-5"], "--axial-load: must be >= 0"),
        (["model", "--axial-load", "100", "--jammed", "11"], "--jammed: must be <= n_rollers"),
        (["simulate", "--duration", "0"], "--duration: must be > 0, got 0.0"),
        (["simulate", "--seed", "-1"], "--seed: must be an integer in [0, "),
    ],
)
def test_a_value_out_of_range_names_its_option(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, argv: list[str], error: str
) -> None:
    """Not the field behind it (axial_load_n, duration_s: found by a review session)."""
    preset = ["--preset", "dong2022-downhole"] if argv[0] == "model" else []
    scene = ["--scene", "nominal-downhole", "--out", str(tmp_path / "bag")]
    assert main([*argv, *(preset if argv[0] == "model" else scene)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"prsm-health: error: {error}") and err.count("\n") == 1
    assert not (tmp_path / "bag").exists()


def test_a_reader_that_left_ends_the_output_quietly() -> None:
    """``prsm-health model-demo | head -1``, with the reader gone before the first write (a
    pipe whose read end is closed): exit 141 and no traceback."""
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        result = subprocess.run(
            [sys.executable, "-m", "prsm_health.cli", "model-demo"],
            stdout=write_end,
            stderr=subprocess.PIPE,
            timeout=60,
            check=False,
        )
    finally:
        os.close(write_end)
    assert result.returncode == 141, result.stderr
    assert b"Traceback" not in result.stderr


BIG = "1" + "0" * 400


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (
            f"actuator: {{preset: dong2022-downhole}}\nnoise: {{current_std_a: {BIG}}}\n",
            "noise.current_std_a: must be a finite number, got an integer of about 401 digits",
        ),
        (
            "actuator: {preset: dong2022-downhole, misalignment_arcmin: [null, 0]}\n",
            "actuator.misalignment_arcmin[0]: must be a number, got None",
        ),
        (
            "actuator: {preset: dong2022-downhole}\nmodel: {initial_jammed_rollers: true}\n",
            "model.initial_jammed_rollers: must be an integer >= 0, got True",
        ),
        (
            "actuator: {preset: dong2022-downhole}\nnoise: {}\nnoise: {current_std_a: 99}\n",
            "params.yaml, line 3, column 1: duplicate key 'noise' (first on line 2)",
        ),
        ("actuator: {preset: [\n", "params.yaml, line 2, column 1: while parsing a flow"),
    ],
)
def test_a_bad_params_file_gives_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, text: str, expected: str
) -> None:
    """The params are read before the bag, so no bag is needed."""
    path = tmp_path / "params.yaml"
    path.write_text(text, encoding="utf-8")
    code, _, err = run(capsys, "replay", str(tmp_path / "no-bag"), "--params", str(path))
    assert code == 2
    assert len(err.strip().splitlines()) == 1
    assert err.startswith("prsm-health: error: ") and expected in err


def test_a_params_file_that_is_not_utf8_is_named(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    path = tmp_path / "latin1.yaml"
    path.write_bytes(b"actuator: {preset: dong\xe9}\n")
    code, _, err = run(capsys, "replay", str(tmp_path / "no-bag"), "--params", str(path))
    assert code == 2
    assert (
        err == f"prsm-health: error: --params: {path}, line 1: not UTF-8 text (byte 0xe9); "
        "save the file as UTF-8\n"
    )


def test_a_bad_preset_file_names_the_file_and_the_key(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    bundled = Path(__file__).parents[1] / "prsm_health/physics/presets/dong2022-downhole.yaml"
    path = tmp_path / "tiny-load.yaml"
    path.write_text(
        bundled.read_text().replace("largest_axial_load_n: 55000.0", "largest_axial_load_n: 1e-300")
    )
    code, _, err = run(capsys, "model", "--preset", str(path), "--axial-load", "1000")
    assert code == 2
    assert len(err.strip().splitlines()) == 1
    assert f"{path}: largest_axial_load_n: must be at least 1 N" in err


def test_help_describes_the_options(capsys: pytest.CaptureFixture[str]) -> None:
    helps = {}
    for command in ([], ["model"], ["play"], ["monitor"]):
        with pytest.raises(SystemExit):
            main([*command, "--help"])
        helps[" ".join(command)] = " ".join(capsys.readouterr().out.split())
    assert "``" not in helps[""] and "planetary roller screw" in helps[""]
    assert "--axial-load N axial load [N]" in helps["model"]
    assert "--speed-rpm RPM screw speed [rpm] (default 300)" in helps["model"]
    assert "--clock-rate HZ /clock messages per second of bag time, with --clock" in helps["play"]
    assert "--timeout S stop after S seconds (default 0: wait forever)" in helps["monitor"]


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["model", "--preset", "x", "--axial-load", "30000k"], "invalid finite number: '30000k'"),
        (["play", "bag", "--rate", "2x"], "must be a finite number > 0, got '2x'"),
        (["monitor", "--count", "1.5"], "must be an integer >= 0, got '1.5'"),
    ],
)
def test_a_number_that_is_none_is_named_readably(
    capsys: pytest.CaptureFixture[str], argv: list[str], expected: str
) -> None:
    """The type functions' names (``invalid _finite value``) are not the message."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.endswith(f"{expected}\n")


def test_a_clock_rate_without_the_clock_is_a_usage_error(
    capsys: pytest.CaptureFixture[str],
) -> None:
    code, _, err = run(capsys, "play", "no-bag", "--clock-rate", "50")
    assert (code, err) == (
        2,
        "prsm-health: error: --clock-rate sets the rate of --clock's /clock: give --clock too\n",
    )


def cli(*args: str) -> subprocess.Popen[str]:
    command = [sys.executable, "-m", "prsm_health", *args]
    return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_play_with_nothing_to_play_fails_naming_the_topics(tmp_path: Path) -> None:
    """It printed "nothing published" and exited with 0."""
    empty = write_bag(tmp_path / "empty", synthetic_run(0.1)[:0])  # the topic, no message
    for args, asked in (((), "any topic"), (("--topics", "/motor_state"), "/motor_state")):
        out, err = cli("play", str(empty), *args).communicate(timeout=60)
        assert (out, err) == (
            "",
            f"prsm-health play: error: nothing to play: no message on {asked} in the bag;"
            " it has /motor_state\n",
        )


def _stop_when_handled(process: subprocess.Popen[str], sig: int) -> tuple[int, str, str]:
    """Send ``sig`` once the command's ROS session handles SIGTERM (the SigCgt mask of
    /proc: a signal before it would end Python uncleanly), then its code and output."""
    deadline = time.monotonic() + 30.0
    status = Path(f"/proc/{process.pid}/status")
    while (
        not int(status.read_text().split("SigCgt:")[1].split()[0], 16) >> (signal.SIGTERM - 1) & 1
    ):
        assert process.poll() is None and time.monotonic() < deadline, process.communicate()
        time.sleep(0.02)
    process.send_signal(sig)
    out, err = process.communicate(timeout=30)
    return process.returncode, out, err


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_play_and_monitor_exit_130_when_interrupted(tmp_path: Path, sig: int) -> None:
    """As simulate, and as a shell reports a command stopped by Ctrl-C (128 + SIGINT); play
    exited with 0 and monitor with 1."""
    bag = write_bag(tmp_path / "bag", synthetic_run(0.01))  # 10 s at --rate 0.001
    code, out, _ = _stop_when_handled(cli("play", str(bag), "--rate", "0.001"), sig)
    assert code == 130 and out.startswith("play interrupted: "), out
    code, _, err = _stop_when_handled(cli("monitor", "--node", "/cli_test_nobody"), sig)
    assert code == 130 and err.startswith("prsm-health monitor: nothing received"), err
