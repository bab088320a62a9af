"""Evidence for each jam onset under the estimator's model (prsm_health/estimation/evidence.py)
on runs of the truth simulator."""

from __future__ import annotations

import pytest

from prsm_health.estimation.estimator import HealthEstimator
from prsm_health.estimation.evidence import onset_evidence
from prsm_health.estimation.params import EstimatorParams, ModelParams
from prsm_health.scenes.scene import scene_from_mapping
from prsm_health.scenes.simulator import simulate
from test.estimation.test_estimator import downhole

#: A jam mid-stroke (the stroke starts at 1.0 s) and one during the support steps between
#: 11.8 s and 14.5 s.
JAMS = [{"time_s": 2.5, "roller": 3}, {"time_s": 13.0, "roller": 7}]


def evidence(radial_load: dict[str, object], radial_load_ratio: float) -> list[float]:
    scene = scene_from_mapping(downhole(jams=JAMS, radial_load=radial_load))
    result = simulate(scene)
    truth = result.truth
    onsets = truth.jam_onsets
    params = EstimatorParams(
        actuator=scene.actuator, model=ModelParams(radial_load_ratio=radial_load_ratio)
    )
    return onset_evidence(
        params,
        result.motor,
        truth.stamp_s[onsets].tolist(),
        truth.jammed_rollers[onsets].tolist(),
        window_s=8.0,
    )


def test_a_jam_in_motion_has_evidence_and_one_at_standstill_without_ripple_has_none() -> None:
    """With the borehole wall's radial load, a jam in steady motion shows in its step and its
    ripple: far more evidence than the prior's 18 nats a block. Without any radial load, a jam
    at standstill changes nothing a larger load could not explain (docs/estimation.md, the
    documented limit): no evidence for it within the window."""
    in_motion, _ = evidence({"type": "wall", "min_n": 2000.0, "max_n": 6000.0}, 0.15)
    assert in_motion > 50.0
    _, at_standstill = evidence({"type": "constant", "value_n": 0.0}, 0.0)
    assert at_standstill < 5.0


def test_the_evidence_for_an_onset_ends_at_the_next_onset() -> None:
    """Each onset's LLR sums the blocks up to the next onset when that comes before the
    window ends (evidence.py's docstring): with onsets 0.6 s apart an 8 s window gives the
    first onset what a window of exactly the gap gives it (20.1 nats; 91.2 if it ran on past
    the second jam). A mutation review found the cut unguarded (the tests' onsets lie 10.5 s
    apart, beyond their window)."""
    jams = [{"time_s": 2.0, "roller": 3}, {"time_s": 2.6, "roller": 7}]
    scene = scene_from_mapping(downhole(duration_s=3.5, jams=jams))
    result = simulate(scene)
    onsets = result.truth.jam_onsets
    stamps = result.truth.stamp_s[onsets].tolist()
    counts = result.truth.jammed_rollers[onsets].tolist()
    params = EstimatorParams(actuator=scene.actuator, model=ModelParams(radial_load_ratio=0.15))
    long_window = onset_evidence(params, result.motor, stamps, counts, window_s=8.0)
    to_the_next = onset_evidence(
        params, result.motor, stamps, counts, window_s=stamps[1] - stamps[0]
    )
    assert long_window[0] == pytest.approx(to_the_next[0], rel=1e-12)
    assert long_window[0] > 0.0


def test_onset_evidence_refuses_inconsistent_onsets() -> None:
    scene = scene_from_mapping(downhole(duration_s=2.0))
    samples = simulate(scene).motor
    params = EstimatorParams(actuator=scene.actuator)
    with pytest.raises(ValueError, match="window_s"):
        onset_evidence(params, samples, [1.0], [1], window_s=0.0)
    with pytest.raises(ValueError, match="one increasing time per count"):
        onset_evidence(params, samples, [1.0, 0.5], [1, 2], window_s=1.0)
    with pytest.raises(ValueError, match="one increasing time per count"):
        onset_evidence(params, samples, [1.0], [1, 2], window_s=1.0)


def test_at_a_jam_rate_of_zero_the_count_only_rises_when_told() -> None:
    """jam_rate_per_h = 0: no hypothesis is ever born, whatever the current shows (the step of
    a jam in motion included); assume_jam_onset sets the count."""
    scene = scene_from_mapping(downhole(duration_s=6.0, jams=JAMS[:1]))
    samples = simulate(scene).motor
    params = EstimatorParams(actuator=scene.actuator, model=ModelParams(jam_rate_per_h=0.0))
    estimator = HealthEstimator(params)
    states = estimator.process(samples[:4000])
    assert states and all(s.jam_probabilities[0] == 1.0 for s in states)
    estimator.assume_jam_onset(1)
    states = estimator.process(samples[4000:]) + estimator.finish()
    assert states and all(s.jam_probabilities[1] == 1.0 for s in states)
    with pytest.raises(ValueError, match="jams only increase"):
        estimator.assume_jam_onset(0)
