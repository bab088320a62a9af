"""The maintenance reset over the node's service, with real processes: a jam identified live
is reset to the count the maintenance leaves, the precision loss to zero, the state saved and
published at once; what cannot be reset is refused with the reason."""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path
from typing import Any

import pytest
from prsm_health_msgs.srv import ResetAfterMaintenance

from prsm_health.outputs import JAMMED_ROLLERS
from prsm_health.ros.node import RESET_SERVICE_QOS
from test.ros.data import ORIGIN_S, synthetic_run, worn_params, write_bag
from test.ros.harness import Listener, NodeProcess, play

SERVICE = "reset_after_maintenance"


def request(jammed: int, *, precision_loss: bool = False, note: str = "") -> object:
    return ResetAfterMaintenance.Request(
        jammed_rollers=jammed,
        reset_precision_loss=precision_loss,
        reset_fatigue_damage=False,
        note=note,
    )


@pytest.mark.timeout(120)
def test_a_reset_after_maintenance_over_the_service(ros: None, tmp_path: Path) -> None:
    state_file = tmp_path / "state.json"
    jam = write_bag(tmp_path / "jam", synthetic_run(4.0, jam_at_s=ORIGIN_S + 2.0))
    later = ORIGIN_S + 6.0
    healthy = write_bag(tmp_path / "healthy", synthetic_run(2.0, start_s=later, from_rest=False))
    listener = Listener("maintained")
    try:
        with NodeProcess(
            tmp_path,
            "maintained",
            params_file=str(worn_params(tmp_path)),
            hardware_id="maintained",
            state_file=str(state_file),
            save_period_s=3600.0,  # only the reset saves during the test
        ) as node:
            node.wait_log("configured")
            listener.wait_matched()
            play(jam, listener=listener)
            listener.wait_for(
                lambda: bool(listener.health) and listener.health[-1]["stamp"] > ORIGIN_S + 3.9,
                20.0,
                "the estimates of the jam bag",
            )
            jammed = listener.health[-1]
            assert jammed["jammed_rollers_most_likely"] == 1
            assert jammed["precision_loss_um"] > 0.0 and jammed["fatigue_damage"] > 0.0

            refused = listener.call(ResetAfterMaintenance, SERVICE, request(11))
            assert not refused.success
            refusal = "nothing reset: jammed_rollers: must be an integer in [0, 10], got 11"
            assert refused.message.startswith(refusal)
            assert not state_file.exists()

            diagnosed = len(listener.diagnostics)  # those before showed the jam, or not yet
            done = listener.call(
                ResetAfterMaintenance, SERVICE, request(0, precision_loss=True, note="roller 3")
            )
            assert done.success, done.message
            assert done.message == "reset after maintenance: jammed rollers 0, precision loss 0"
            node.wait_log("(note: 'roller 3')")
            saved = json.loads(state_file.read_text())["estimator"]  # saved at once
            assert [h["count"] for h in saved["hypotheses"]] == [0]
            assert saved["degradation"]["precision_loss_m"] == 0.0
            assert saved["degradation"]["fatigue_damage"] == pytest.approx(
                jammed["fatigue_damage"], rel=0.05
            )
            # Published at once, without new input: the operator sees the reset.
            listener.wait_for(
                lambda: listener.health[-1]["jammed_rollers_most_likely"] == 0,
                10.0,
                "the reset state on the health topic",
            )
            reset, last = listener.health[-1], listener.health[-2]
            assert reset["stamp"] == last["stamp"]  # the last estimate's: time does not go back
            assert reset["jammed_rollers_probability"][0] == 1.0
            assert reset["precision_loss_um"] == 0.0
            assert reset["fatigue_damage"] == last["fatigue_damage"]

            def jam_status() -> dict[str, Any]:
                """The jammed-rollers status of the latest diagnostics since the reset call."""
                arrays = [{s["name"]: s for s in d["status"]} for d in listener.diagnostics]
                return arrays[-1].get(JAMMED_ROLLERS, {}) if arrays[diagnosed:] else {}

            listener.wait_for(
                lambda: "no jammed roller" in jam_status().get("message", ""),
                10.0,
                "the reset count in the diagnostics",
            )
            assert jam_status()["values"]["jammed_rollers_most_likely"] == "0"

            before = len(listener.health)
            play(healthy, listener=listener)
            listener.wait_for(
                lambda: bool(listener.health) and listener.health[-1]["stamp"] > later + 1.9,
                20.0,
                "the estimates of the healthy bag",
            )
            after = listener.health[before:]
            assert all(h["jammed_rollers_most_likely"] == 0 for h in after)
            assert 0.0 < after[-1]["precision_loss_um"] < jammed["precision_loss_um"]
            assert after[-1]["fatigue_damage"] > jammed["fatigue_damage"]

            # A long note is logged cut, with its length (1 MB was one log line of 1 MB).
            long = listener.call(ResetAfterMaintenance, SERVICE, request(0, note="x" * 100_000))
            assert long.success, long.message
            node.wait_log("... (100000 characters)")
            assert "x" * 501 not in node.log()

        with NodeProcess(
            tmp_path, "unconfigured", autostart=False, state_file=str(tmp_path / "other.json")
        ) as node:
            node.wait_log("autostart is false")
            client = listener.node.create_client(ResetAfterMaintenance, f"/unconfigured/{SERVICE}")
            try:  # the service exists from configure to cleanup
                assert not client.wait_for_service(timeout_sec=2.0)
            finally:
                listener.node.destroy_client(client)
    finally:
        listener.close()


@pytest.mark.timeout(120)
def test_a_reset_whose_save_failed_is_saved_by_the_next_period(ros: None, tmp_path: Path) -> None:
    """A reset changes the state without new samples (once no block is pending): if its save
    fails (here a file stands where the state's directory was), the periodic save must still
    write it once it can, although the sample count is the one saved before."""
    folder = tmp_path / "state"
    folder.mkdir()
    state_file = folder / "state.json"
    jam = write_bag(tmp_path / "jam", synthetic_run(2.0, jam_at_s=ORIGIN_S + 1.0))
    listener = Listener("retried")
    try:
        with NodeProcess(
            tmp_path,
            "retried",
            hardware_id="retried",
            state_file=str(state_file),
            save_period_s=0.5,
        ) as node:
            node.wait_log("configured")
            listener.wait_matched()
            play(jam, listener=listener)

            def saved_counts() -> list[int] | None:
                """The jam counts of the saved state's hypotheses (None: none readable)."""
                try:
                    hypotheses = json.loads(state_file.read_text())["estimator"]["hypotheses"]
                except (OSError, ValueError):
                    return None
                return [h["count"] for h in hypotheses]

            listener.wait_for(
                lambda: bool(listener.health) and listener.health[-1]["stamp"] > ORIGIN_S + 1.9,
                20.0,
                "the estimates of the bag",
            )
            # A first reset closes the pending block (new samples counted) and is saved.
            assert listener.call(ResetAfterMaintenance, SERVICE, request(1)).success
            listener.wait_for(lambda: saved_counts() == [1], 10.0, "the first reset saved")
            shutil.rmtree(folder)
            folder.write_text("in the way")
            done = listener.call(ResetAfterMaintenance, SERVICE, request(0))
            assert done.success, done.message
            node.wait_log("cannot save the state")
            folder.unlink()
            folder.mkdir()
            listener.wait_for(
                lambda: saved_counts() == [0], 10.0, "the reset state saved by the periodic save"
            )
    finally:
        listener.close()


@pytest.mark.timeout(120)
def test_a_burst_of_resets_is_answered_every_one(ros: None, tmp_path: Path) -> None:
    """50 requests at once from one caller: with the services' default queue (KEEP_LAST 10)
    the node answered 10 and the other callers waited for ever. The caller reads its answers
    2 s later, so they wait in its client's queue, which must hold them too (with the
    default, CI's caller lost the answers that came before it spun)."""
    listener = Listener("burst")
    try:
        with NodeProcess(
            tmp_path, "burst", hardware_id="burst", state_file=str(tmp_path / "state.json")
        ) as node:
            node.wait_log("configured")
            client = listener.node.create_client(
                ResetAfterMaintenance, f"/burst/{SERVICE}", qos_profile=RESET_SERVICE_QOS
            )
            assert client.wait_for_service(timeout_sec=10.0)
            futures = [client.call_async(request(0, note=f"burst {i}")) for i in range(50)]
            time.sleep(2.0)  # a caller busy elsewhere: every answer comes before it reads one
            listener.wait_for(
                lambda: all(f.done() for f in futures), 30.0, "an answer to every request"
            )
            assert all(f.result().success for f in futures)
            assert node.log().count("reset after maintenance: jammed rollers 0") == 50
    finally:
        listener.close()
