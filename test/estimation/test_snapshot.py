"""Saving and resuming the estimator's state (what the node persists across restarts)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from prsm_health.actuator import Actuator
from prsm_health.estimation.estimator import HealthEstimator, SnapshotError
from prsm_health.estimation.params import EstimatorParams
from prsm_health.physics.presets import load_preset
from prsm_health.signals import MotorSamples


def params(preset: str = "dong2022-downhole") -> EstimatorParams:
    return EstimatorParams(actuator=Actuator(preset=load_preset(preset), wear_acceleration=1e5))


def moving(seconds: float, start_s: float = 0.0) -> MotorSamples:
    rng = np.random.default_rng(int(start_s))
    n = int(seconds * 1000)
    t = start_s + np.arange(n) / 1000.0
    return MotorSamples(t, 6.0 + rng.normal(0, 0.05, n), 150.0 + rng.normal(0, 0.2, n), 150.0 * t)


def test_a_restored_estimator_continues_the_precision_loss() -> None:
    first = HealthEstimator(params())
    before = first.process(moving(3.0))
    saved = json.loads(json.dumps(first.snapshot()))  # survives JSON
    resumed = HealthEstimator(params())
    resumed.restore(saved)
    after = resumed.process(moving(1.0, start_s=3.0))
    assert before[-1].precision_loss_m > 0.0
    assert after[0].precision_loss_m >= before[-1].precision_loss_m
    assert after[0].samples_accepted > before[-1].samples_accepted
    assert after[0].axial_load_n == pytest.approx(before[-1].axial_load_n, rel=0.05)


def test_the_ripple_axes_survive_a_restart() -> None:
    """A jammed hypothesis' ripple axis (its phase, hypotheses.ripple_walk) is saved and
    restored; a state saved without axes resumes with them unknown."""
    first = HealthEstimator(params())
    first.process(moving(1.0))
    saved = first.snapshot()
    saved["hypotheses"][0]["ripple_axis"] = [0.6, -0.8]
    resumed = HealthEstimator(params())
    resumed.restore(json.loads(json.dumps(saved)))
    np.testing.assert_array_equal(resumed._bank.hypotheses[0].ripple_axis, [0.6, -0.8])
    for entry in saved["hypotheses"]:
        del entry["ripple_axis"]
    resumed.restore(saved)
    assert all(h.ripple_axis is None for h in resumed._bank.hypotheses)


def test_a_state_of_another_actuator_is_refused() -> None:
    saved = HealthEstimator(params()).snapshot()
    with pytest.raises(SnapshotError, match="another actuator"):
        HealthEstimator(params("li2020-jamming")).restore(saved)


@pytest.mark.parametrize(
    "damage",
    [
        lambda s: s.pop("hypotheses"),
        lambda s: s["hypotheses"][0].update(x=[1.0]),
        lambda s: s["hypotheses"][0].update(P=[[float("nan")] * 5] * 5),
        lambda s: s["degradation"].update(precision_loss_m="a lot"),
        lambda s: s.update(format=99),
        lambda s: s["hypotheses"][0].update(ripple_axis=[0.0, 2.0]),
    ],
)
def test_a_malformed_state_is_refused(damage: object) -> None:
    saved = HealthEstimator(params()).snapshot()
    damage(saved)  # type: ignore[operator]
    with pytest.raises(SnapshotError):
        HealthEstimator(params()).restore(saved)
