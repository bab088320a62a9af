"""The state file: atomic saves; bad files kept aside, never replaced silently."""

from __future__ import annotations

import dataclasses
import errno
import json
import math
import os
import time
from pathlib import Path

import pytest

from prsm_health.estimation.estimator import HealthEstimator
from prsm_health.estimation.params import EstimatorParams, params_from_mapping
from prsm_health.outputs import Level, PersistenceHealth, persistence_status
from prsm_health.ros.persistence import (
    FORMAT,
    StateStore,
    default_state_file,
)
from test.ros.data import synthetic_run


@pytest.fixture(scope="module")
def params() -> EstimatorParams:
    return params_from_mapping(
        {"actuator": {"preset": "dong2022-downhole", "wear_acceleration": 1e6}}
    )


@pytest.fixture(scope="module")
def worn(params: EstimatorParams) -> HealthEstimator:
    estimator = HealthEstimator(params)
    estimator.process(synthetic_run(2.0))
    assert estimator.snapshot()["degradation"]["precision_loss_m"] > 0.0
    return estimator


def test_save_then_restore_round_trips(
    tmp_path: Path, params: EstimatorParams, worn: HealthEstimator
) -> None:
    store = StateStore(tmp_path / "deep" / "left.json", "left")
    store.save(worn)
    document = json.loads(store.path.read_text())
    assert document["format"] == FORMAT
    assert document["hardware_id"] == "left"
    assert document["estimator"] == worn.snapshot()  # JSON keeps every float exactly
    assert list(tmp_path.joinpath("deep").iterdir()) == [store.path]  # no temporary left
    fresh = HealthEstimator(params)
    outcome = store.restore(fresh)
    assert outcome.restored and outcome.kept_aside is None
    assert fresh.snapshot()["degradation"] == worn.snapshot()["degradation"]


def test_the_last_estimate_is_saved_with_the_state(
    tmp_path: Path, params: EstimatorParams, worn: HealthEstimator
) -> None:
    """The snapshot holds no estimate: the last one is saved beside it for the diagnostics of
    a restart. One JSON cannot hold is left out; a file without one resumes without it."""
    last = worn.current_state()
    assert last is not None
    store = StateStore(tmp_path / "left.json", "left")
    store.save(worn, last)
    outcome = store.restore(HealthEstimator(params))
    assert outcome.restored and outcome.last_estimate == last

    store.save(worn, dataclasses.replace(last, axial_load_n=math.nan))
    assert json.loads(store.path.read_text())["last_estimate"] is None
    assert store.restore(HealthEstimator(params)).last_estimate is None
    document = json.loads(store.path.read_text())
    del document["last_estimate"]  # saved before it existed
    store.path.write_text(json.dumps(document))
    outcome = store.restore(HealthEstimator(params))
    assert outcome.restored and outcome.last_estimate is None


@pytest.mark.parametrize(
    "change",
    [
        {"axial_load_n": "30 kN"},
        {"jam_probabilities": [0.5, None]},
        {"event": 9},
        {"unknown_field": 1.0},
        {"stamp_s": True},
        # Values no estimator makes (accepted until a helper's review: the diagnostics then
        # showed a stamp of 300 digits, or a possible jam from these probabilities).
        {"stamp_s": 1e300},
        {"jam_probabilities": [-1.0, 2.0, 0.0]},
        {"jam_probabilities": [0.5, 0.5]},
        {"axial_load_std_n": -1.0},
        {"efficiency": 1.5},
    ],
)
def test_a_malformed_last_estimate_loses_only_itself(
    tmp_path: Path, params: EstimatorParams, worn: HealthEstimator, change: dict[str, object]
) -> None:
    """The state is restored, the last estimate (the diagnostics' copy) dropped and named. The
    whole file was kept aside: precision loss, fatigue and jam probabilities started fresh for
    a field only the diagnostics read (or for one of a newer version)."""
    store = StateStore(tmp_path / "left.json", "left")
    store.save(worn, worn.current_state())
    document = json.loads(store.path.read_text())
    document["last_estimate"].update(change)
    store.path.write_text(json.dumps(document))
    resumed = HealthEstimator(params)
    outcome = store.restore(resumed)
    assert outcome.restored and outcome.kept_aside is None and outcome.last_estimate is None
    assert "last estimate of" in outcome.problem and "malformed last estimate" in outcome.problem
    assert resumed.snapshot()["degradation"] == worn.snapshot()["degradation"]
    status = persistence_status(
        PersistenceHealth(str(store.path), restored=True, problem=outcome.problem), "left", 0.0
    )
    assert status.level == Level.OK and status.message.startswith("resumed from the state file; ")


def test_missing_file_is_a_fresh_start(tmp_path: Path, params: EstimatorParams) -> None:
    outcome = StateStore(tmp_path / "none.json", "left").restore(HealthEstimator(params))
    assert not outcome.restored and outcome.kept_aside is None


@pytest.mark.timeout(10)
def test_a_state_file_that_is_not_a_regular_file_is_kept_aside(
    tmp_path: Path, params: EstimatorParams
) -> None:
    """A FIFO at the state file's path: reading it blocked configure for ever, and the node
    no longer answered SIGINT or SIGTERM (a helper's review)."""
    path = tmp_path / "left.json"
    os.mkfifo(path)
    outcome = StateStore(path, "left").restore(HealthEstimator(params))
    assert not outcome.restored and outcome.kept_aside is not None
    assert "is not a regular file" in outcome.problem and not path.exists()


@pytest.mark.parametrize(
    ("content", "reason"),
    [
        ("{not json", "unusable state file"),
        ('{"format": "prsm_health.state/1", "hardware_id": "left", "estimator": []}', "no est"),
        ('{"format": "other"}', "not a prsm_health.state/1"),
        ("[" * 100_000, "nested too deeply"),  # json.loads raised RecursionError
    ],
)
def test_corrupt_file_is_kept_aside(
    tmp_path: Path, params: EstimatorParams, content: str, reason: str
) -> None:
    path = tmp_path / "left.json"
    path.write_text(content)
    estimator = HealthEstimator(params)
    before = estimator.snapshot()
    outcome = StateStore(path, "left").restore(estimator)
    assert not outcome.restored
    assert outcome.kept_aside is not None
    assert outcome.kept_aside.name.startswith("left.json.corrupt-")
    assert outcome.kept_aside.read_text() == content
    assert not path.exists()
    assert reason in outcome.problem
    assert estimator.snapshot() == before


def test_bad_files_kept_aside_in_the_same_second_are_numbered_apart(
    tmp_path: Path, params: EstimatorParams, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Pins that a kept-aside name already taken is numbered on until a free one (-2, -3):
    with the clock standing still, three bad state files in turn are all kept, each with its
    content. A mutation review found it unguarded (one number tried only: the third went to
    the second's name and replaced it)."""
    monkeypatch.setattr(time, "strftime", lambda _format, _time: "20260101T000000Z")
    store = StateStore(tmp_path / "left.json", "left")
    kept = []
    for n in range(3):
        store.path.write_text(f"bad state {n}")
        outcome = store.restore(HealthEstimator(params))
        assert not outcome.restored and outcome.kept_aside is not None
        kept.append(outcome.kept_aside)
    names = [path.name for path in kept]
    stamp = "left.json.corrupt-20260101T000000Z"
    assert names == [stamp, f"{stamp}-2", f"{stamp}-3"]
    assert [path.read_text() for path in kept] == ["bad state 0", "bad state 1", "bad state 2"]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(names)


def test_malformed_estimator_state_is_kept_aside(
    tmp_path: Path, params: EstimatorParams, worn: HealthEstimator
) -> None:
    store = StateStore(tmp_path / "left.json", "left")
    store.save(worn)
    document = json.loads(store.path.read_text())
    document["estimator"]["hypotheses"] = "garbage"
    store.path.write_text(json.dumps(document))
    outcome = store.restore(HealthEstimator(params))
    assert outcome.kept_aside is not None
    assert outcome.problem.startswith(f"unusable state file {store.path}: ")


@pytest.mark.parametrize(
    ("section", "key", "value", "problem"),
    [
        # A uint64 message field cannot carry it: every HealthEstimate publish failed.
        (None, "samples_accepted", 2**64, "sample counters"),
        # Published as 0 um ("OK, 0 um of the budget"): 1e303 m is infinite in um.
        ("degradation", "precision_loss_m", 1e303, "degradation values"),
    ],
)
def test_values_the_outputs_cannot_carry_are_kept_aside(
    tmp_path: Path,
    params: EstimatorParams,
    worn: HealthEstimator,
    section: str | None,
    key: str,
    value: float,
    problem: str,
) -> None:
    store = StateStore(tmp_path / "left.json", "left")
    store.save(worn)
    document = json.loads(store.path.read_text())
    state = document["estimator"]
    (state if section is None else state[section])[key] = value
    store.path.write_text(json.dumps(document))
    outcome = store.restore(HealthEstimator(params))
    assert outcome.kept_aside is not None and problem in outcome.problem


def test_state_of_the_same_screw_under_another_drive_train_is_resumed_in_part(
    tmp_path: Path, params: EstimatorParams, worn: HealthEstimator
) -> None:
    """It was set aside as an "unusable state file" (the node started from zero wear)."""
    store = StateStore(tmp_path / "left.json", "left")
    store.save(worn, worn.current_state())
    recalibrated = params_from_mapping(
        {
            "actuator": {
                "preset": "dong2022-downhole",
                "wear_acceleration": 1e6,
                "drive_train": {"torque_constant_nm_per_a": 0.2},
            }
        }
    )
    fresh = HealthEstimator(recalibrated)
    outcome = store.restore(fresh)
    assert outcome.restored and outcome.kept_aside is None
    # Which part changed (it said "the drive train, misalignment or ripple states differ").
    changed = (
        "the drive train changed since the state was saved: the precision loss, fatigue "
        "damage and jam-count probabilities are resumed, the load is estimated afresh"
    )
    assert outcome.problem == changed and outcome.last_estimate is not None
    assert fresh.snapshot()["degradation"] == worn.snapshot()["degradation"]
    assert list(tmp_path.iterdir()) == [store.path]
    health = PersistenceHealth(str(store.path), restored=True, problem=outcome.problem)
    status = persistence_status(health, "left", 0.0)
    assert status.message == f"resumed from the state file; {changed}"


def test_state_of_another_actuator_or_hardware_is_kept_aside_as_foreign(
    tmp_path: Path, params: EstimatorParams, worn: HealthEstimator
) -> None:
    """Sound states of another screw (a wrong preset given by mistake) or hardware id were
    kept as ".corrupt": they are not, and resume once moved back under matching parameters."""
    fractal = params_from_mapping({"actuator": {"preset": "meng2021-fractal"}})
    StateStore(tmp_path / "left.json", "left").save(HealthEstimator(fractal))
    outcome = StateStore(tmp_path / "left.json", "left").restore(HealthEstimator(params))
    assert outcome.kept_aside is not None and outcome.kept_aside.name.startswith(
        "left.json.foreign-"
    )
    assert "another screw" in outcome.problem and "move it back" in outcome.problem
    os.replace(outcome.kept_aside, tmp_path / "left.json")  # the right preset again
    assert StateStore(tmp_path / "left.json", "left").restore(HealthEstimator(fractal)).restored

    StateStore(tmp_path / "right.json", "right").save(worn)
    os.replace(tmp_path / "right.json", tmp_path / "left.json")
    outcome = StateStore(tmp_path / "left.json", "left").restore(HealthEstimator(params))
    assert outcome.kept_aside is not None
    assert "hardware_id 'right'" in outcome.problem
    StateStore(tmp_path / "right.json", "right").save(worn)
    os.replace(tmp_path / "right.json", tmp_path / "left.json")
    assert StateStore(tmp_path / "left.json", "left").restore(HealthEstimator(params)).kept_aside
    assert len(list(tmp_path.glob("left.json.foreign-*"))) == 2  # both kept, distinct names


def test_failed_save_leaves_the_old_file(
    tmp_path: Path, params: EstimatorParams, worn: HealthEstimator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A disk error while syncing the new state (injected: the tests run as root on a healthy
    disk, where no real write fails) leaves the previous state and no temporary file."""
    store = StateStore(tmp_path / "left.json", "left")
    store.save(HealthEstimator(params))
    old = store.path.read_text()

    def failing_fsync(fd: int) -> None:
        raise OSError(errno.EIO, "injected I/O error")

    monkeypatch.setattr(os, "fsync", failing_fsync)
    with pytest.raises(OSError, match="injected"):
        store.save(worn)
    assert store.path.read_text() == old
    assert list(tmp_path.iterdir()) == [store.path]


def test_a_file_where_the_folder_goes_is_named(tmp_path: Path, params: EstimatorParams) -> None:
    (tmp_path / "sub").write_text("not a folder")
    store = StateStore(tmp_path / "sub" / "deeper" / "left.json", "left")
    with pytest.raises(NotADirectoryError, match="a file stands where the state's folder goes"):
        store.save(HealthEstimator(params))


def test_default_state_file(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("XDG_STATE_HOME", "/var/state")
    assert default_state_file("left") == Path("/var/state/prsm_health/left.json")
    monkeypatch.delenv("XDG_STATE_HOME")
    assert default_state_file("left") == Path.home() / ".local/state/prsm_health/left.json"
