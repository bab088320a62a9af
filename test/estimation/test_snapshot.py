"""Saving and resuming the estimator's state (what the node persists across restarts)."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math

import numpy as np
import pytest

from prsm_health.actuator import Actuator
from prsm_health.estimation.estimator import HealthEstimator
from prsm_health.estimation.params import EstimatorParams, Fidelity
from prsm_health.estimation.snapshot import SOME_PART, ForeignStateError, SnapshotError
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
    assert resumed.restore(saved) == ()  # the whole state: nothing differs
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


def test_the_measured_speed_noise_survives_a_restart() -> None:
    """A restarted estimator keeps the speed noise it measured in motion (a coarse encoder's
    2 rad/s; else the parameter's 0.2 would hold for 2.6 s of motion, when the inertia
    torque's noise made false jams); a state saved before it measured from scratch."""
    rng = np.random.default_rng(11)
    samples = moving(4.0)
    samples.speed_rad_s[:] = 150.0 + rng.normal(0.0, 2.0, len(samples))
    first = HealthEstimator(params())
    first.process(samples)
    measured = first.input_measures.speed_noise_std_rad_s
    assert measured == pytest.approx(2.0, rel=0.1)
    saved = json.loads(json.dumps(first.snapshot()))
    resumed = HealthEstimator(params())
    resumed.restore(saved)
    assert resumed.input_measures.speed_noise_std_rad_s == measured
    del saved["speed_noise_var_rad2_s2"]
    older = HealthEstimator(params())
    older.restore(saved)
    assert older.input_measures.speed_noise_std_rad_s is None


def test_the_measured_current_noise_survives_a_restart() -> None:
    """As the speed's: a current ten times noisier than the parameter, measured before the
    save, sets the spike threshold after the restore too (else its tails were rejected as
    spikes again until it was measured anew)."""
    samples = moving(1.0)
    samples.current_a[:] += np.random.default_rng(12).normal(0.0, 0.5, len(samples))
    first = HealthEstimator(params())
    first.process(samples)
    measured = first._blocker.faults.current_noise.measured_std
    assert measured == pytest.approx(0.5, rel=0.15)
    resumed = HealthEstimator(params())
    resumed.restore(json.loads(json.dumps(first.snapshot())))
    assert resumed._blocker.faults.current_noise.measured_std == measured


def test_a_state_of_another_screw_is_refused_as_foreign_unless_damaged() -> None:
    saved = HealthEstimator(params()).snapshot()
    # Said as it is (it read "malformed state: SnapshotError('the state belongs to ...')").
    with pytest.raises(ForeignStateError, match=r"^the state belongs to another screw"):
        HealthEstimator(params("li2020-jamming")).restore(saved)
    # A damaged one is damaged, whoever's it was (it was called foreign, "resumes once moved
    # back", which it never would).
    saved["degradation"]["precision_loss_m"] = -1.0
    with pytest.raises(SnapshotError, match="degradation values") as info:
        HealthEstimator(params("li2020-jamming")).restore(saved)
    assert not isinstance(info.value, ForeignStateError)


def _other_screw(base: EstimatorParams, part: str) -> EstimatorParams:
    """``base`` with one value of the preset's ``part`` (one that defines the screw) changed."""
    preset = base.actuator.preset
    geometry, friction = preset.geometry, preset.friction
    wear, fatigue = preset.wear, preset.fatigue
    other = {
        "geometry": dataclasses.replace(
            preset, geometry=dataclasses.replace(geometry, nut_outer_radius_m=32.0e-3)
        ),
        "friction": dataclasses.replace(
            preset, friction=dataclasses.replace(friction, sliding_friction_coefficient=0.12)
        ),
        "wear": dataclasses.replace(
            preset,
            wear=dataclasses.replace(
                wear,
                archard_coefficient=10.0 * wear.archard_coefficient,
                adhesive_wear_coefficient=10.0 * wear.adhesive_wear_coefficient,
            ),
        ),
        "fatigue": dataclasses.replace(
            preset, fatigue=dataclasses.replace(fatigue, stress_exponent=7.0)
        ),
    }[part]
    return dataclasses.replace(base, actuator=dataclasses.replace(base.actuator, preset=other))


@pytest.mark.parametrize("part", ["geometry", "friction", "wear", "fatigue"])
def test_a_state_is_foreign_under_a_preset_that_differs_in_any_part_of_the_screw(
    part: str,
) -> None:
    """Pins that every part of the preset that defines the screw (geometry, friction, wear,
    fatigue) is in the screw's fingerprint: a state saved under one preset and restored under
    a preset with one value of any of them changed is refused as another screw's, not resumed
    in part with its degradation. A mutation review found the wear unguarded (left out of the
    fingerprint, a state restored under wear coefficients x10 was resumed as a partial
    restore)."""
    base = params()
    saved = json.loads(json.dumps(HealthEstimator(base).snapshot()))
    other = _other_screw(base, part)
    assert getattr(other.actuator.preset, part) != getattr(base.actuator.preset, part)
    with pytest.raises(ForeignStateError, match=r"^the state belongs to another screw"):
        HealthEstimator(other).restore(saved)
    assert HealthEstimator(base).restore(saved) == ()  # its own screw resumes it whole


def test_a_state_saved_before_the_screw_fingerprint_still_resumes() -> None:
    """Files saved before 2026-11-26 have only the actuator's digest, of this tuple: it must
    not change, or every such file would be set aside at the upgrade."""
    base = params()
    preset, actuator = base.actuator.preset, base.actuator
    old = (preset.geometry, preset.friction, preset.wear, preset.fatigue)
    old += (actuator.drive_train, actuator.misalignment, base.radial_terms)
    saved = HealthEstimator(base).snapshot()
    assert saved["actuator"] == hashlib.sha256(repr(old).encode()).hexdigest()[:16]
    assert saved["actuator"] == "cef0f10e4fa49d5a"  # what the code of 85945b2 saved for it
    del saved["screw"]
    assert HealthEstimator(base).restore(saved) == ()
    with pytest.raises(SnapshotError, match=r"^the state belongs to another actuator \(the pre"):
        HealthEstimator(_changed(base, "drive train")).restore(saved)


def _changed(base: EstimatorParams, change: str) -> EstimatorParams:
    actuator = base.actuator
    if change == "drive train":
        drive_train = dataclasses.replace(actuator.drive_train, torque_constant_nm_per_a=0.2)
        return dataclasses.replace(
            base, actuator=dataclasses.replace(actuator, drive_train=drive_train)
        )
    # No ripple states: the filters' states have another dimension.
    return dataclasses.replace(base, fidelity=Fidelity(radial_terms="off"))


@pytest.mark.parametrize("change", ["drive train", "ripple states"])
def test_the_same_screw_under_other_parameters_keeps_its_degradation_and_jams(change: str) -> None:
    """A recalibrated torque constant set the whole state aside as unusable: the precision
    loss and fatigue accumulated over the screw's life and its known jams were lost."""
    first = HealthEstimator(params())
    first.process(moving(3.0))
    first.reset_after_maintenance(2, reset_precision_loss=False, reset_fatigue_damage=False)
    worn = first._degradation.state
    assert worn.precision_loss_m > 0.0 and worn.fatigue_damage > 0.0
    saved = json.loads(json.dumps(first.snapshot()))
    other = _changed(params(), change)
    resumed = HealthEstimator(other)
    assert resumed.restore(saved) == (change,)  # only the screw's part, and which part changed
    assert resumed._degradation.state == worn
    assert [(h.count, h.log_prob) for h in resumed._bank.hypotheses] == [(2, 0.0)]
    fresh = HealthEstimator(other)._bank.hypotheses[0].filter
    np.testing.assert_array_equal(resumed._bank.hypotheses[0].filter.x, fresh.x)
    np.testing.assert_array_equal(resumed._bank.hypotheses[0].filter.P, fresh.P)
    after = resumed.process(moving(1.0, start_s=3.0))
    assert after and all(math.isfinite(s.axial_load_n) for s in after)
    assert after[0].precision_loss_m >= worn.precision_loss_m


def test_an_unpruned_bank_restarts_every_count_with_its_probability() -> None:
    unpruned = dataclasses.replace(params(), fidelity=Fidelity(prune_hypotheses=False))
    saved = HealthEstimator(unpruned).snapshot()
    saved["hypotheses"][0]["log_probability"] = math.log(0.25)
    saved["hypotheses"][1]["log_probability"] = math.log(0.75)
    resumed = HealthEstimator(_changed(unpruned, "drive train"))
    assert resumed.restore(saved) == ("drive train",)
    probabilities = [math.exp(h.log_prob) for h in resumed._bank.hypotheses]
    assert [h.count for h in resumed._bank.hypotheses] == list(range(11))
    assert probabilities[:2] == pytest.approx([0.25, 0.75]) and sum(probabilities[2:]) == 0.0


@pytest.mark.parametrize(
    "damage",
    [
        lambda s: s.pop("hypotheses"),
        lambda s: s["hypotheses"][0].update(x=[1.0]),
        lambda s: s["hypotheses"][0].update(P=[[float("nan")] * 5] * 5),
        lambda s: s["degradation"].update(precision_loss_m="a lot"),
        # Losses and damages only grow from zero: the estimate would report a negative loss.
        lambda s: s["degradation"].update(precision_loss_m=-1.0),
        lambda s: s["degradation"].update(fatigue_damage=-5.0),
        lambda s: s.update(format=99),
        lambda s: s["hypotheses"][0].update(ripple_axis=[0.0, 2.0]),
        # Parsed by json.loads; the probabilities would all become NaN.
        lambda s: [h.update(log_probability=float("-inf")) for h in s["hypotheses"]],
        lambda s: [h.update(log_probability=None) for h in s["hypotheses"]],
        # Finite, but it overflows once symmetrised.
        lambda s: s["hypotheses"][0].update(P=[[1e308] * 5] * 5),
        # Fewer rejection reasons (an older file): the counters would fail at the next one.
        lambda s: s.update(samples_rejected=[0, 0, 0]),
        lambda s: s.update(samples_accepted=-1),
        # Each below 2^62, their sum beyond int64: every block after overflowed (a review).
        lambda s: s.update(samples_rejected=[2**62 - 1] * 3 + [0] * 2),
        # A variance is >= 0 and finite; the median over them would set every acceleration's.
        lambda s: s.update(speed_noise_var_rad2_s2=[4.0, -1.0]),
        lambda s: s.update(speed_noise_var_rad2_s2=[float("nan")]),
        lambda s: s.update(speed_noise_var_rad2_s2=["loud"]),
        lambda s: s.update(speed_noise_var_rad2_s2=4.0),
        lambda s: s.update(current_noise_var_a2=[float("inf")]),
        lambda s: s.update(current_noise_var_a2=[-0.1]),
    ],
)
def test_a_malformed_state_is_refused(damage: object) -> None:
    saved = HealthEstimator(params()).snapshot()
    damage(saved)  # type: ignore[operator]
    with pytest.raises(SnapshotError):
        HealthEstimator(params()).restore(saved)


def test_a_restored_ripple_far_beyond_its_prior_gives_finite_estimates() -> None:
    """Ripple states of 1e80 are within the snapshot's bounds; judging their phase squared
    their amplitude twice and overflowed (OverflowError in the next block)."""
    estimator = HealthEstimator(params())
    n = 3000
    t = np.arange(n) / 1000.0
    speed = np.full(n, 300.0)
    samples = MotorSamples(t, np.full(n, 10.0) + 0.05 * np.sin(t), speed, 300.0 * t)
    estimator.process(samples[:1500])
    saved = estimator.snapshot()
    for h in saved["hypotheses"]:
        h["x"][3] = h["x"][4] = 1e80
    restored = HealthEstimator(params())
    restored.restore(saved)
    states = restored.process(samples[1500:]) + restored.finish()
    assert states and all(math.isfinite(s.axial_load_n) for s in states)


@pytest.mark.parametrize("damaged", ["x", "P", "load"])
def test_a_restored_load_beyond_the_divergence_bound_is_forgotten(damaged: str) -> None:
    """A state file's filter states (x) or covariances (P) of 9.9e99, within the snapshot's
    bounds but beyond the divergence bound, in every hypothesis: resumed as they were, the
    wear integrated at them gave 2e73 um of precision loss (or a standard deviation of 6e25
    um), saved for good (found by a review session). The resume re-acquires such a load from
    zero, as after a divergence; a load of -3 MN alone was caught by the divergence test."""
    first = HealthEstimator(params())
    before = first.process(moving(2.0))
    saved = json.loads(json.dumps(first.snapshot()))
    for h in saved["hypotheses"]:
        if damaged == "x":
            h["x"] = [9.9e99] * 5
        elif damaged == "P":
            h["P"] = [[9.9e99] * 5 for _ in range(5)]
        else:
            h["x"][0] = -3e6
    resumed = HealthEstimator(params())
    resumed.restore(saved)
    after = resumed.process(moving(2.0, start_s=2.0)) + resumed.finish()
    loss_um = [s.precision_loss_m * 1e6 for s in (before[-1], after[-1])]
    assert loss_um[1] - loss_um[0] < 2.0 * loss_um[0]  # 2 s more of the same wear
    assert after[-1].precision_loss_std_m < 10.0 * before[-1].precision_loss_std_m
    assert abs(after[-1].axial_load_n - before[-1].axial_load_n) < 0.05 * params().load_scale_n


def test_an_unpruned_bank_with_ruled_out_counts_is_saved_and_restored() -> None:
    """Without pruning the impossible counts stay at probability zero (log -inf, which JSON
    cannot hold): saved as null, restored as zero."""
    unpruned = dataclasses.replace(params(), fidelity=Fidelity(prune_hypotheses=False))
    first = HealthEstimator(unpruned)
    first.process(moving(1.0))
    first.reset_after_maintenance(0, reset_precision_loss=False, reset_fatigue_damage=False)
    text = json.dumps(first.snapshot(), allow_nan=False)  # the node's StateStore writes so
    resumed = HealthEstimator(unpruned)
    resumed.restore(json.loads(text))
    zero = [h.count for h in first._bank.hypotheses if h.log_prob == -math.inf]
    assert zero and [h.count for h in resumed._bank.hypotheses] == [
        h.count for h in first._bank.hypotheses
    ]
    assert [h.count for h in resumed._bank.hypotheses if h.log_prob == -math.inf] == zero


def test_a_load_that_moved_while_the_node_was_down_is_not_taken_for_a_jam() -> None:
    """The input stage's clock is not saved, so the first block after a restore follows a
    hole of unknown length: the load's derivatives are forgotten and jam evidence waits while
    the load is found again, as the original does after the same silence. Without that, the
    restored estimator predicts 40 ms from the saved state, and a load 50 % larger after the
    restart is a torque step that only a jam explains."""
    first = HealthEstimator(params())
    first.process(moving(3.0))
    first.finish()
    resumed = HealthEstimator(params())
    resumed.restore(first.snapshot())
    later = moving(1.0, start_s=13.0)
    later = MotorSamples(
        later.stamp_s, 1.5 * later.current_a, later.speed_rad_s, later.position_rad
    )
    for states in (first.process(later), resumed.process(later)):
        assert max(1.0 - s.jam_probabilities[0] for s in states) < 1e-6
        assert states[-1].axial_load_n == pytest.approx(1.5 * 25_000.0, rel=0.1)


def test_the_saved_estimate_brought_up_to_now_takes_the_filters_load() -> None:
    """After a restore under another torque constant a maintenance reset published the saved
    estimate's load (25,015 +- 59 N) while the filters had started afresh (0 +- 55 kN)."""
    first = HealthEstimator(params())
    saved_estimate = first.process(moving(3.0))[-1]
    saved = json.loads(json.dumps(first.snapshot()))
    whole = HealthEstimator(params())
    assert whole.restore(saved) == ()
    now = whole.current_state(saved_estimate)
    assert now is not None and now.axial_load_n == pytest.approx(saved_estimate.axial_load_n)
    assert now.axial_load_std_n == pytest.approx(saved_estimate.axial_load_std_n)
    partial = HealthEstimator(_changed(params(), "drive train"))
    assert partial.restore(saved) == ("drive train",)
    afresh = partial.current_state(saved_estimate)
    assert afresh is not None and afresh.axial_load_n == 0.0
    assert afresh.axial_load_std_n > 50e3 > 100.0 * saved_estimate.axial_load_std_n
    assert afresh.precision_loss_m == saved_estimate.precision_loss_m  # the screw's, kept


def test_a_state_saved_before_the_parts_says_some_part_changed() -> None:
    """Files saved before 2026-11-26 (third session) do not say which part of the actuator
    they were saved under: the restore says one of them changed, not which."""
    saved = HealthEstimator(params()).snapshot()
    del saved["parts"]
    assert HealthEstimator(_changed(params(), "drive train")).restore(saved) == (SOME_PART,)
