"""Inputs stop: every estimator status goes STALE within the timeout; inputs resume: it
recovers (real processes, the node's clock is the system clock here). The same node shows
~/health throttled to health_rate_hz."""

from __future__ import annotations

import dataclasses
import re
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from prsm_health.bags.writer import BagWriter, write_motor_states
from prsm_health.outputs import AXIAL_LOAD, INPUT_HEALTH, JAMMED_ROLLERS, STATUS_NAMES
from test.ros.data import ORIGIN_S, synthetic_run, write_bag
from test.ros.harness import Listener, NodeProcess, play

STALE_TIMEOUT_S = 0.5
DIAGNOSTICS_RATE_HZ = 10.0
HEALTH_RATE_HZ = 5.0
HARDWARE_ID = "stale_test"


def params_file(tmp: Path, **diagnostics: float) -> Path:
    """The bundled parameters with other diagnostics thresholds."""
    lines = ["actuator: {preset: dong2022-downhole}", "diagnostics:"]
    lines += [f"  {key}: {value}" for key, value in diagnostics.items()]
    path = tmp / "params.yaml"
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.timeout(90)
def test_stale_then_recovered(ros: None, tmp_path: Path) -> None:
    first = write_bag(tmp_path / "first", synthetic_run(2.0))
    later = ORIGIN_S + 4.0
    second = write_bag(tmp_path / "second", synthetic_run(2.0, start_s=later, from_rest=False))
    listener = Listener()
    try:
        with NodeProcess(
            tmp_path,
            params_file=str(params_file(tmp_path, stale_timeout_s=STALE_TIMEOUT_S)),
            hardware_id=HARDWARE_ID,
            state_file=str(tmp_path / "state.json"),
            diagnostics_rate_hz=DIAGNOSTICS_RATE_HZ,
            health_rate_hz=HEALTH_RATE_HZ,
        ) as node:
            node.wait_log("configured")

            def series() -> list[tuple[float, dict[str, dict[str, Any]]]]:
                """(node-clock stamp, estimator statuses) of every diagnostics message."""
                return [
                    (d["stamp"], {s["name"]: s for s in d["status"] if s["name"] in STATUS_NAMES})
                    for d in listener.diagnostics
                    if d["status"][0]["hardware_id"] == HARDWARE_ID
                ]

            def stale(statuses: dict[str, dict[str, Any]]) -> bool:
                levels = {s["level"] for s in statuses.values()}
                return len(statuses) == len(STATUS_NAMES) and levels == {"STALE"}

            listener.wait_for(lambda: bool(series()) and stale(series()[-1][1]), 20.0, "STALE")
            assert series()[-1][1][AXIAL_LOAD]["message"].startswith("stale: no input yet")

            before = len(series())
            started = time.monotonic()
            play(first, listener=listener)
            played_s = time.monotonic() - started
            listener.wait_for(lambda: stale(series()[-1][1]), 5.0, "STALE after the inputs")
            # ~/health at HEALTH_RATE_HZ, not every estimate (2 s of bag: 50 blocks): at most
            # one per tick of the node's timer while the bag played (longer than the bag's 2 s
            # on a busy machine), at least one per tick of those 2 s but the first and last.
            stamps = [h["stamp"] for h in listener.health]
            assert 8 <= len(stamps) <= played_s * HEALTH_RATE_HZ + 2, (stamps, played_s)
            assert stamps == sorted(set(stamps))  # each estimate once, the newest at each tick
            during = series()[before:]
            last_fresh = max(i for i, (_, st) in enumerate(during) if not stale(st))
            (fresh_at, fresh), (stale_at, first_stale) = during[last_fresh : last_fresh + 2]
            assert stale(first_stale)
            assert not {s["level"] for s in fresh.values()} & {"STALE", "ERROR"}
            # The node's own clock: STALE from the first diagnostics after the inputs are older
            # than the timeout, not before, not later.
            age = [float(st[INPUT_HEALTH]["values"]["input_age_s"]) for st in (fresh, first_stale)]
            assert age[0] <= STALE_TIMEOUT_S < age[1]
            assert age[1] - age[0] == pytest.approx(stale_at - fresh_at, abs=1e-6)
            message = first_stale[JAMMED_ROLLERS]["message"]
            assert message.startswith("stale: no input for")
            assert "last: no jammed roller" in message

            # Recovered while the second bag plays. (Not the latest message: the inputs stop
            # again at its end, and the player's exit may take longer than the timeout.)
            before = len(series())
            play(second, listener=listener)

            def recovered() -> list[dict[str, dict[str, Any]]]:
                return [st for _, st in series()[before:] if not stale(st)]

            listener.wait_for(lambda: bool(recovered()), 5.0, "recovery")
            assert {s["level"] for s in recovered()[0].values()} <= {"OK", "WARN"}
            assert node.alive()
            # Stamps on the node's clock: not taken for a clock in the wrong unit.
            inputs = [st[INPUT_HEALTH] for _, st in series() if INPUT_HEALTH in st]
            assert not [s["message"] for s in inputs if "stamps advance" in s["message"]]
            rates = [float(s["values"]["stamp_rate"]) for s in inputs]
            known = [r for r in rates if r >= 0.0]
            # Across the pause between the bags (2 s of stamps in less of the node's clock,
            # the end-to-end rate read 2.3 once) as well: the median of the moves.
            assert known and all(0.5 < r < 2.0 for r in known), rates
    finally:
        listener.close()


#: The input health's words for stamps on another clock, and the rate they name.
STAMP_RATE = r"stamps advance (\S+) s per second received \(a clock in the wrong unit\?\)"


@pytest.mark.timeout(90)
def test_stamps_on_another_clock_are_named(ros: None, tmp_path: Path) -> None:
    """Messages published at 1 kHz whose stamps advance 1 us each (a clock in the wrong unit):
    the input health warns, naming the stamps' rate against the node's clock (it read
    "1000 Hz, 0 rejected" while no block completed). The rate named is 1e-3 as far as the
    player keeps its pace (0.000995 with a busy machine: within 10 %)."""
    samples = synthetic_run(3.0)
    slow = dataclasses.replace(samples, stamp_s=ORIGIN_S + 1e-6 * np.arange(len(samples)))
    bag = tmp_path / "slow"
    with BagWriter(bag) as writer:  # logged 1 ms apart: played at 1 kHz
        logged = np.round(samples.stamp_s * 1e9).astype(np.int64)
        write_motor_states(writer, slow, receive_time_ns=logged)
    listener = Listener()
    try:
        state_file = str(tmp_path / "state.json")
        with NodeProcess(tmp_path, hardware_id=HARDWARE_ID, state_file=state_file) as node:
            node.wait_log("configured")
            play(bag, listener=listener)
            messages = [
                s["message"]
                for d in listener.diagnostics
                for s in d["status"]
                if s["name"] == INPUT_HEALTH and s["hardware_id"] == HARDWARE_ID
            ]
            found = (re.search(STAMP_RATE, m) for m in messages)
            named = [float(match.group(1)) for match in found if match]
            assert named and all(abs(rate - 1e-3) < 1e-4 for rate in named), messages
    finally:
        listener.close()
