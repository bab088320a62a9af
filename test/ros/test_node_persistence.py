"""Persistence with real processes: kill -9 and restart, SIGTERM, corrupt and foreign files."""

from __future__ import annotations

import json
import signal
from pathlib import Path

import pytest

from prsm_health.estimation.estimator import HealthEstimator
from prsm_health.estimation.params import params_from_mapping
from prsm_health.outputs import PERSISTENCE
from prsm_health.ros.persistence import StateStore
from test.ros.data import ORIGIN_S, synthetic_run, write_bag
from test.ros.harness import Listener, NodeProcess, play, start_player, stop_process

SAVE_PERIOD_S = 0.5
BLOCK_S = 0.04


def worn_params(tmp: Path) -> Path:
    """Parameters whose wear is a million times faster, so that seconds show a loss."""
    path = tmp / "params.yaml"
    path.write_text("actuator: {preset: dong2022-downhole, wear_acceleration: 1.0e6}\n")
    return path


def saved_loss_um(state_file: Path) -> float:
    document = json.loads(state_file.read_text())
    return float(document["estimator"]["degradation"]["precision_loss_m"]) * 1e6


@pytest.mark.timeout(120)
def test_kill9_restart_resumes_and_sigterm_saves(ros: None, tmp_path: Path) -> None:
    state_file = tmp_path / "state.json"
    params = str(worn_params(tmp_path))
    first = write_bag(tmp_path / "first", synthetic_run(8.0))
    resumed_at = ORIGIN_S + 10.0
    second = write_bag(tmp_path / "second", synthetic_run(2.0, start_s=resumed_at, from_rest=False))
    listener = Listener()
    try:
        node = NodeProcess(
            tmp_path,
            params_file=params,
            hardware_id="persist",
            state_file=str(state_file),
            save_period_s=SAVE_PERIOD_S,
        )
        with node:
            node.wait_log("configured")
            player = start_player(first)
            try:
                listener.wait_for(
                    lambda: (
                        bool(listener.health)
                        and listener.health[-1]["stamp"] > ORIGIN_S + 3.0
                        and state_file.exists()
                    ),
                    30.0,
                    "3 s of estimates and a saved state",
                )
                node.process.send_signal(signal.SIGKILL)
                node.process.wait(10)
            finally:
                stop_process(player)
        listener.spin(0.2)  # estimates still in flight
        before_kill = listener.health[-1]
        saved = saved_loss_um(state_file)
        rate_um_per_s = before_kill["precision_loss_rate_um_per_h"] / 3600.0
        assert rate_um_per_s > 0.1  # the accelerated wear shows
        # At most one save period (plus a batch and the timer's jitter) of wear is lost.
        lost = before_kill["precision_loss_um"] - saved
        assert 0.0 <= lost <= rate_um_per_s * (SAVE_PERIOD_S + 0.25)

        listener.health.clear()
        with NodeProcess(
            tmp_path,
            params_file=params,
            hardware_id="persist",
            state_file=str(state_file),
            save_period_s=3600.0,  # below, only the shutdown can have saved
        ) as node:
            node.wait_log("resumed from")
            play(second, listener=listener)
            listener.wait_for(lambda: len(listener.health) > 10, 10.0, "estimates after restart")
            first_after = listener.health[0]
            assert first_after["stamp"] > resumed_at
            # Continues from the saved value: one block of wear later.
            assert saved < first_after["precision_loss_um"]
            assert first_after["precision_loss_um"] <= saved + 2 * rate_um_per_s * BLOCK_S
            mtime = state_file.stat().st_mtime_ns
            assert stop_process(node.process, signal.SIGTERM) == 0
        assert state_file.stat().st_mtime_ns > mtime
        assert saved_loss_um(state_file) >= listener.health[-1]["precision_loss_um"]
        assert "Traceback" not in node.log()
    finally:
        listener.close()


@pytest.mark.timeout(60)
def test_corrupt_and_foreign_state_files_are_kept_aside(ros: None, tmp_path: Path) -> None:
    corrupt = tmp_path / "corrupt.json"
    corrupt_text = '{"format": "prsm_health.state/1", "hardware_id": "corrupt", "estim'
    corrupt.write_text(corrupt_text)
    foreign = tmp_path / "foreign.json"
    other = HealthEstimator(params_from_mapping({"actuator": {"preset": "meng2021-fractal"}}))
    StateStore(foreign, "foreign").save(other)
    foreign_text = foreign.read_text()
    listener = Listener()
    try:
        nodes = [
            NodeProcess(tmp_path, name, hardware_id=name, state_file=str(path))
            for name, path in (("corrupt", corrupt), ("foreign", foreign))
        ]
        try:
            for node in nodes:
                node.wait_log("starting fresh")
                assert node.alive()

            def reported(hardware_id: str) -> bool:
                status = listener.statuses(hardware_id).get(PERSISTENCE)
                return status is not None and status["level"] == "WARN"

            listener.wait_for(lambda: reported("corrupt") and reported("foreign"), 20.0, "WARN")
        finally:
            for node in nodes:
                stop_process(node.process)
    finally:
        listener.close()

    for name, problem, text in (
        ("corrupt", "unusable state file", corrupt_text),
        ("foreign", "another actuator", foreign_text),
    ):
        status = listener.statuses(name)[PERSISTENCE]
        kept = Path(status["values"]["kept_corrupt"])
        assert kept.parent == tmp_path and kept.name.startswith(f"{name}.json.corrupt-")
        assert kept.read_text() == text  # the bad file is kept as it was
        assert problem in status["message"] and "started fresh" in status["message"]
        log = next(n for n in nodes if n.name == name).log()
        assert problem in log and str(kept) in log
    # The fresh states were saved at shutdown, beside the kept files.
    assert saved_loss_um(corrupt) == 0.0
    assert json.loads(foreign.read_text())["estimator"] != json.loads(foreign_text)["estimator"]
