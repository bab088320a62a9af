"""The estimator end to end on runs of the truth simulator (real physics, sensors, faults)."""

from __future__ import annotations

import dataclasses
import itertools
import math
from typing import Any

import numpy as np
import pytest

from prsm_health.benchmark import (
    chunked,
    cycle_period_s,
    one_jam_scenes,
    params_for,
    scored,
    two_jam_scenes,
)
from prsm_health.estimation.estimate import EstimateEvent, HealthState
from prsm_health.estimation.estimator import (
    GATED_BLOCKS_BEFORE_RESET,
    REACQUIRE_S,
    REVERSAL_WITHIN_S,
    HealthEstimator,
)
from prsm_health.estimation.inputs import Block, RejectReason
from prsm_health.estimation.measurement import TorqueModel
from prsm_health.estimation.metrics import Metrics, score
from prsm_health.estimation.params import EstimatorParams, Fidelity, FilterParams, ModelParams
from prsm_health.scenes.envelope import OTHER_SCREW, RELEASE_SETTINGS
from prsm_health.scenes.scene import Scene, scene_from_mapping, varied_scene
from prsm_health.scenes.simulator import SimulationChunk, simulate
from prsm_health.signals import MotorSamples
from test.estimation.chunks import fed_in_chunks

RPM = 2.0 * math.pi / 60.0


def downhole(**changes: Any) -> dict[str, Any]:
    document: dict[str, Any] = {
        "name": "test-downhole",
        "actuator": {"preset": "dong2022-downhole", "wear_acceleration": 1.0e5},
        "duration_s": 24.0,
        "seed": 5,
        "profile": {
            "type": "downhole_cycle",
            "stroke_m": 0.1,
            "speed_rpm": [300.0, 400.0],
            "traction_load_n": [20000.0, 45000.0],
            "support_s": 1.0,
        },
        "radial_load": {"type": "wall", "min_n": 2000.0, "max_n": 6000.0, "period_s": 6.0},
        "load_noise": {"relative_std": 0.015, "bandwidth_hz": 0.2},
    }
    document.update(changes)
    return document


def run(document: dict[str, Any], **model: Any) -> tuple[list[HealthState], Metrics, Any]:
    scene = scene_from_mapping(document)
    result: SimulationChunk = simulate(scene)
    params = EstimatorParams(actuator=scene.actuator, model=ModelParams(**model))
    estimator = HealthEstimator(params)
    states = estimator.process(result.motor) + estimator.finish()
    metrics = score(
        states,
        result.truth,
        rated_load_n=params.rated_load_n,
        largest_screw_speed_rad_s=scene.actuator.preset.largest_speed_rpm * RPM,
    )
    return states, metrics, result


def test_a_jam_mid_stroke_is_identified_at_once_and_the_load_stays_accurate() -> None:
    states, metrics, _ = run(downhole(jams=[{"time_s": 4.0, "roller": 2}]))
    (jam,) = metrics.jams
    assert jam.delay_s is not None and jam.delay_s < 0.5
    assert metrics.false_jam_declarations == 0
    assert metrics.load_rmse_percent_rated < 2.0
    assert metrics.load_nees_consistent
    assert states[-1].jam_probabilities[1] > 0.99


def test_a_healthy_run_declares_no_jam_and_tracks_load_and_wear() -> None:
    states, metrics, _result = run(downhole(), wear_coefficient_factor=1.0)
    assert metrics.false_jam_declarations == 0
    assert max(1.0 - s.jam_probabilities[0] for s in states) < 1e-3
    assert metrics.load_rmse_percent_rated < 0.5
    assert abs(metrics.precision_loss_error_percent) < 2.0
    assert metrics.precision_loss_coverage_2sigma == 1.0
    losses = [s.precision_loss_m for s in states]
    assert all(b >= a for a, b in itertools.pairwise(losses))


def reversing(period_s: float, duration_s: float) -> dict[str, Any]:
    """A sinusoidal speed of 300 rpm that reverses through zero every half period, against a
    load of 20 kN that resists the motion (a step of 40 kN where the speed crosses zero)."""
    return downhole(
        name="test-reversing",
        duration_s=duration_s,
        seed=12,
        profile={"type": "sine", "speed_amplitude_rpm": 300.0, "period_s": period_s},
    )


@pytest.mark.parametrize(("period_s", "duration_s"), [(4.0, 12.0), (40.0, 50.0)])
def test_a_load_that_flips_as_the_motion_reverses_is_no_jam(
    period_s: float, duration_s: float
) -> None:
    """The load model has no steps: its derivatives move it smoothly, and at a stroke start
    only faster. Before the load was forgotten where the motion reverses, a reversal on this
    run was a divergence or, where a fresh jam's ripple explained the step better than the old
    load, a false jam: up to five jammed rollers and a load 210 kN off (61 % RMSE over 40 s).
    A reversal every 2 s crosses zero inside a block (the block reverses); every 20 s, the
    speed takes 80 ms to cross the standstill band, and the reversal is the first block that
    moves against the last moving one."""
    states, metrics, _ = run(reversing(period_s, duration_s))
    assert metrics.false_jam_declarations == 0
    assert metrics.load_rmse_percent_rated < 0.5
    assert not any(s.event == EstimateEvent.DIVERGENCE_RECOVERED for s in states)


def test_the_estimate_of_the_block_where_the_motion_reverses_is_honest() -> None:
    """The block in which the speed crosses zero holds samples of both loads (standstill,
    since not all its samples move one way): its estimate forgets the old load instead of
    holding it with the steady motion's confidence. Before, the old load stood there 40 kN
    off at a standard deviation of 60-300 N; now the truth at the block's mean stamp lies
    within 2 sigma at each of the five crossings."""
    states, _, result = run(reversing(4.0, 12.0))
    crossings = [s for s in states if s.event == EstimateEvent.STANDSTILL and s.stamp_s > 1.0]
    assert len(crossings) == 5
    for state in crossings:
        truth = np.interp(state.stamp_s, result.truth.stamp_s, result.truth.axial_load_n)
        assert abs(state.axial_load_n - truth) < 2.0 * state.axial_load_std_n


def block(stamp_s: float, direction: int, **changes: Any) -> Block:
    """A 40 ms block at ``stamp_s`` moving in ``direction`` (0: standing) at 150 rad/s."""
    return Block(stamp_s, 0.04, 40, 0.0, 150.0 * direction, 0.0, 1.0, 0.0, direction, **changes)


@pytest.mark.parametrize(
    ("gap_s", "time_reset", "reverses"),
    [
        (0.04, False, True),  # straight from one block to the next
        (REVERSAL_WITHIN_S - 0.02, False, True),
        (REVERSAL_WITHIN_S + 0.02, False, False),
        (2.0, False, False),
        (0.04, True, False),  # a new time line starts afresh anyway
    ],
)
def test_a_reversal_is_a_stop_shorter_than_its_window_on_one_time_line(
    gap_s: float, time_reset: bool, reverses: bool
) -> None:
    """The first block moving against the last moving one (``gap_s`` after it) is a reversal
    (its load may have stepped) if it comes less than REVERSAL_WITHIN_S after it on the same
    time line; after a longer stop the load builds up as a stroke starts, and forgetting it
    there cost the downhole runs accuracy (docs/estimation.md, "Reversals")."""
    estimator = HealthEstimator(EstimatorParams(actuator=scene_from_mapping(downhole()).actuator))

    assert not estimator._reverses(block(1.0, 1))
    assert not estimator._reverses(block(1.04, 1))
    assert not estimator._reverses(block(1.08, 0))  # standing: no verdict yet
    assert estimator._reverses(block(1.04 + gap_s, -1, time_reset=time_reset)) == reverses
    assert estimator._reverses(block(5.0, 0, reverses=True))  # both ways inside the block


def test_a_reversal_starts_no_load_build_up() -> None:
    """After a stop the traction load builds up as the stroke starts (the transition density
    for its first ``model.load_transition_s``); after a reversal the load was forgotten and is
    found again from the torque, on the steady density. On it, half of each 2 s half-cycle
    of a sine stroke ran on the transition density, where the healthy hypothesis' load
    followed a jammed roller's ripple and the jam was lost (sine-jam: 10.7 % RMSE)."""
    estimator = HealthEstimator(EstimatorParams(actuator=scene_from_mapping(downhole()).actuator))

    def transition(b: Block) -> bool:
        return estimator._load_transition(b, reverses=estimator._reverses(b))

    assert transition(block(1.0, 1))  # a stroke starts
    assert not transition(block(2.5, 1))  # steady motion
    assert transition(block(2.54, 0))  # standing
    assert not transition(block(2.58, -1))  # moving back 0.08 s after the last moving block
    assert not transition(block(3.0, -1))
    assert transition(block(4.0, 1))  # after a stop of a second a stroke starts


def test_a_jam_on_a_reversing_stroke_stays_found_through_the_reversals() -> None:
    """A jam at 10.3 s of the sine stroke, in motion, is found at once and kept through the
    four reversals after it, with the load within 2 % (sine-jam of the benchmark's envelope).
    With the transition density after each reversal the healthy hypothesis, at 1.3 times the
    load, explained the torque as well, and the count was back at 0 from 13.6 s on."""
    document = reversing(4.0, 20.0) | {"jams": [{"time_s": 10.3, "roller": 3}]}
    states, metrics, _ = run(document)
    (jam,) = metrics.jams
    assert jam.delay_s is not None and jam.delay_s < 0.5
    after = [s for s in states if s.stamp_s > jam.onset_s + jam.delay_s]
    assert all(s.jammed_rollers_most_likely == 1 for s in after)
    assert metrics.load_rmse_percent_rated < 2.0


@pytest.mark.parametrize(("factor", "self_locked"), [(1.5, False), (0.0, True)])
def test_no_self_locked_count_at_a_load_beyond_the_plausible(
    factor: float, self_locked: bool
) -> None:
    """sudden-jam with supports of 0.5 s: after a short stop a third jam, self-locked at an
    assisting load beyond twice the preset's largest (the true one resists), outweighs the
    true two within seconds: a false jam and 44 % load RMSE. Bounded at 1.5 times the
    preset's largest load, that hypothesis is dropped. (Seed 40; the benchmark envelope's
    seed 46, 29 % without the bound, no longer goes there since the block's acceleration
    takes the median of three samples at each end, 2026-11-29; seeds 43, 47, 48, 50, 54 and
    57 of the twenty from 40 still do.)"""
    scene = varied_scene(
        "sudden-jam",
        "short-supports",
        profile={"type": "downhole_cycle", "support_s": 0.5},
        seed=40,
    )
    result = simulate(scene)
    params = EstimatorParams(
        actuator=scene.actuator, model=ModelParams(plausible_load_factor=factor)
    )
    states, _ = chunked(params, result.motor)
    metrics = scored(states, result.truth, params)
    assert (metrics.false_jam_declarations > 0) == self_locked
    assert (metrics.load_rmse_percent_rated > 2.0) == self_locked
    assert (max(abs(s.axial_load_n) for s in states) > 1.5 * params.load_scale_n) == self_locked


@pytest.mark.parametrize("set_for_it", [True, False])
def test_a_load_released_fast_at_a_stroke_end(set_for_it: bool) -> None:
    """A healthy screw whose load is released in 0.2 s at each stroke end (the scenes: 0.5 s):
    in steady motion that release costs the load model hundreds of nats, and a jam explains
    it more cheaply (a false jam and the load 20-46 % off from there). With the decelerating
    blocks on the transition density, raised tenfold (docs/estimation.md, "A load released
    fast"), no jam is declared and the load is right; with those blocks predicted at their
    mean load (the load bends within them), its standard deviation is honest too (NEES 3-5
    without)."""
    document = downhole(profile=downhole()["profile"] | {"load_ramp_s": 0.2})
    _, metrics, _ = run(document, **(RELEASE_SETTINGS if set_for_it else {}))
    assert (metrics.false_jam_declarations == 0) == set_for_it
    assert (metrics.load_rmse_percent_rated < 0.5) == set_for_it
    assert metrics.load_nees_consistent == set_for_it


def test_a_time_reset_standing_still_leaves_no_last_moving_block() -> None:
    """After a clock that jumped back by 0.4 s, the first moving block (against the last one
    of the old time line, 0.3 s before it on the stamps) is no reversal: that block belongs
    to another time line, and the time between them is not known. (The check compared the
    stamps across the reset where the reset block stood still.)"""
    estimator = HealthEstimator(EstimatorParams(actuator=scene_from_mapping(downhole()).actuator))

    assert not estimator._reverses(block(10.0, 1))
    assert not estimator._reverses(block(9.6, 0, time_reset=True))
    assert not estimator._reverses(block(9.7, -1))


def test_without_radial_load_a_jam_is_told_by_its_step() -> None:
    document = downhole(
        radial_load={"type": "constant", "value_n": 0.0},
        jams=[{"time_s": 4.0, "roller": 2}],
    )
    _, metrics, _ = run(document, radial_load_ratio=0.0)
    (jam,) = metrics.jams
    assert jam.delay_s is not None and jam.delay_s < 0.5
    assert metrics.false_jam_declarations == 0


def test_a_jam_at_standstill_without_ripple_is_not_identifiable() -> None:
    """The documented limit (docs/estimation.md): no radial load, no misalignment, the jam
    during a support step. When the next stroke starts, a healthy screw at a load larger by the
    jam's torque ratio explains the current as well as a jammed one: the count stays at the
    prior's choice (0), and the load reads high by about that ratio (+38 % here). If this test
    fails because the jam is found, the estimator learned something: update the docs."""
    document = downhole(
        radial_load={"type": "constant", "value_n": 0.0},
        jams=[{"time_s": 13.0, "roller": 2}],  # support steps between 11.8 s and 14.5 s
    )
    states, _, result = run(document, radial_load_ratio=0.0)
    truth = result.truth
    later = [s for s in states if 16.0 < s.stamp_s < 18.0]
    assert later and truth.jammed_rollers[-1] == 1
    assert all(s.jammed_rollers_most_likely == 0 for s in later)
    true_load = np.interp([s.stamp_s for s in later], truth.stamp_s, truth.axial_load_n)
    ratio = np.array([s.axial_load_n for s in later]) / true_load
    assert 1.3 < float(np.median(ratio)) < 1.45


def second_jam_delays(scene: Scene, setting: str, values: tuple[float, ...]) -> list[float | None]:
    """The second jam's identification delay on ``scene`` with the model's ``setting`` at each
    of ``values`` (the first jam, in motion, identified at once each time)."""
    result = simulate(scene)
    delays = []
    for value in values:
        params = params_for(scene, Fidelity())
        model = dataclasses.replace(params.model, **{setting: value})
        params = dataclasses.replace(params, model=model)
        states, _ = chunked(params, result.motor)
        first, second = scored(states, result.truth, params).jams
        assert first.delay_s is not None and first.delay_s < 0.5
        delays.append(second.delay_s)
    return delays


def test_a_second_jam_that_turns_the_ripple_is_identified() -> None:
    """two-jam-8 of the benchmark: roller 9 seizes in steady motion at 16 kN, 11 s after
    roller 1, while the wall's radial load falls from 7 to 3 kN. With its phase known, the
    ripple of one jammed roller may follow the radial load in amplitude but not turn; the
    second roller turns it, and count 2 becomes the most likely within a second. With the
    ripple free to turn (the phase walk as fast as the amplitude walk), count 1 follows with
    its ripple and load and the jam is never identified (docs/estimation.md)."""
    walk = "ripple_phase_walk_radial_n_per_sqrt_s"
    along = ModelParams().ripple_walk_radial_n_per_sqrt_s
    identified, missed = second_jam_delays(
        two_jam_scenes(8)[7], walk, (getattr(ModelParams(), walk), along)
    )
    assert identified is not None and identified < 2.0
    assert missed is None


def test_on_another_screw_the_ripple_prior_is_that_screws_and_finds_a_jam() -> None:
    """two-jam-2 of the benchmark on meng2022-misalignment's screw, whose jammed roller makes
    a ripple 3.2 times smaller against its load torque than dong2022-downhole's: with the
    ripple's prior and walks scaled by the physics core to this screw, the first jam (at
    standstill) is identified within the cycle; with them as large, relative to the load
    torque, as on the downhole screw, it is never identified (docs/estimation.md, "The
    ripple's size, from the physics")."""
    scene = two_jam_scenes(2, preset=OTHER_SCREW)[1]
    cycle_s = cycle_period_s(scene)
    assert cycle_s is not None
    result = simulate(scene)
    params = params_for(scene, Fidelity())
    downhole = params_for(two_jam_scenes(1)[0], Fidelity())
    larger = TorqueModel(downhole).ripple_relative(1.0) / TorqueModel(params).ripple_relative(1.0)
    assert 3.0 < larger < 3.5
    model = params.model
    as_on_downhole = dataclasses.replace(
        model,
        ripple_prior_radial_n=model.ripple_prior_radial_n * larger,
        ripple_walk_radial_n_per_sqrt_s=model.ripple_walk_radial_n_per_sqrt_s * larger,
        ripple_phase_walk_radial_n_per_sqrt_s=model.ripple_phase_walk_radial_n_per_sqrt_s * larger,
    )
    first_delays = []
    for setting in (params, dataclasses.replace(params, model=as_on_downhole)):
        states, _ = chunked(setting, result.motor)
        metrics = scored(states, result.truth, setting)
        assert metrics.false_jam_declarations == 0
        first_delays.append(metrics.jams[0].delay_s)
    scaled, unscaled = first_delays
    assert scaled is not None and scaled < cycle_s
    assert unscaled is None


def test_a_second_jam_at_standstill_that_turns_the_ripple_is_identified() -> None:
    """two-jam-13 of the benchmark: roller 10 seizes in motion, roller 4 at standstill 18.7 s
    later; their ripple is turned by 72 degrees. While the next stroke's load builds up, count 1
    could shrink its ripple's amplitude and turn its phase in (c, s) at the cost of an absolute
    move across the phasor; updated in polar coordinates there, its phase keeps its own
    uncertainty and count 2 is identified within the cycle. With the phase walking ten times
    faster, count 1 turns and the jam is missed (docs/estimation.md, "Polar updates while a
    stroke starts")."""
    scene = two_jam_scenes(13)[12]
    cycle_s = cycle_period_s(scene)
    assert cycle_s is not None
    walk = "ripple_phase_walk_rad_per_sqrt_s"
    identified, missed = second_jam_delays(scene, walk, (getattr(ModelParams(), walk), 0.3))
    assert identified is not None and identified < cycle_s
    assert missed is None


def test_the_load_at_standstill_is_held_to_its_band_at_the_updated_load() -> None:
    """With two jammed rollers the stiction band, evaluated at the load predicted past the
    stroke's end, made every standstill uninformative: errors of up to 11 kN (RMSE 4.5 kN)
    on a load held at zero, where the estimates now stay within tens of newtons."""
    two_jams = [{"time_s": 2.0, "roller": 2}, {"time_s": 3.0, "roller": 7}]
    states, metrics, _ = run(downhole(jams=two_jams))
    assert [jam.delay_s is not None and jam.delay_s < 0.1 for jam in metrics.jams] == [True] * 2
    assert sum(s.event == EstimateEvent.STANDSTILL for s in states) > 10
    assert metrics.load_standstill_max_error_n < 200.0
    assert metrics.load_standstill_coverage_2sigma >= 0.95


def test_three_jammed_rollers_self_lock_the_screw_at_standstill() -> None:
    """Their sliding torque grows faster with the load than the load torque (docs/estimation.md):
    any held load explains a held torque, and the standstill update does not narrow the band
    at a small updated load (without that guard the standstill estimates of three jammed
    rollers claimed their load to 40 N)."""
    model = TorqueModel(DEFAULT)
    still = Block(0.0, 0.5, 500, 0.0, 0.0, 0.0, 1.0, 0.0, direction=0)
    moving = dataclasses.replace(still, motor_speed_rad_s=150.0, direction=1)
    for load in (1e3, 20e3, 50e3):
        x = np.r_[load, np.zeros(model.dim - 1)]
        locked = [model.predict(x, still, jammed).self_locking for jammed in range(4)]
        assert locked == [False, False, False, True]
        assert not model.predict(x, moving, 3).self_locking
    three = [{"time_s": 2.0, "roller": 2}, {"time_s": 3.0, "roller": 7}]
    states, _, _ = run(downhole(jams=[*three, {"time_s": 3.5, "roller": 4}]))
    locked = [
        s.axial_load_std_n
        for s in states
        if s.event == EstimateEvent.STANDSTILL and s.jammed_rollers_most_likely == 3
    ]
    assert len(locked) > 5 and max(locked) > 1e3


def test_a_jam_at_standstill_survives_a_slow_stroke() -> None:
    """one-jam-3 of the held-out seed 7877, cut to 45 s: roller 5 seizes at standstill
    (29.5 s), and through the next, slow stroke at 2-3.5 kN of radial load "count 1 since the
    standstill", with the right load, loses some tenths of a nat a block. With the established
    floor at 1e-13 it survives until the wall's load makes its ripple plain and is identified
    within the cycle; at the old floor, 1e-11, it was pruned seconds before that and the jam is
    not identified in the run (docs/estimation.md, pruning)."""
    scene = one_jam_scenes(3, 45.0, seed=7877)[2]
    result = simulate(scene)
    cycle_s = cycle_period_s(scene)
    assert cycle_s is not None
    delays = []
    for floor in (FilterParams().min_established_probability, 1e-11):
        params = params_for(scene, Fidelity())
        settings = dataclasses.replace(params.filter, min_established_probability=floor)
        states, _ = chunked(dataclasses.replace(params, filter=settings), result.motor)
        (jam,) = scored(states, result.truth, params).jams
        delays.append(jam.delay_s)
    kept, pruned = delays
    assert kept is not None and kept < cycle_s
    assert pruned is None


def test_sensor_faults_are_counted_and_never_reach_the_outputs() -> None:
    document = downhole(
        sensor_faults={
            "dropouts": [{"start_s": 3.0, "duration_s": 0.7}],
            "nonfinite": [{"time_s": 4.0, "field": "all", "value": float("nan"), "samples": 5}],
            "spikes": [{"time_s": 5.0, "field": "current_a", "value": 30.0}],
            "stuck": [{"start_s": 6.0, "duration_s": 0.3, "field": "current_a"}],
            "time_jumps": [{"time_s": 10.0, "jump_s": -0.5}],
        }
    )
    states, _, _ = run(document)
    for s in states:
        values = [s.axial_load_n, s.axial_load_std_n, s.precision_loss_m, s.efficiency, s.nis]
        assert all(math.isfinite(v) for v in values)
    last = states[-1]
    assert last.samples_rejected >= 5 + 1 + 280
    assert any(s.event == EstimateEvent.TIME_RESET for s in states)


@pytest.mark.parametrize("where", ["against", "first", "last", "inside"])
def test_one_wild_speed_sample_moves_neither_the_load_nor_the_count(where: str) -> None:
    """One wrong speed sample in the heaviest stroke. Every estimate stays within 0.5 % of the
    rated load of the run without it, with no jam declared.
    - against: -500 rad/s against the motion (as in the sensor-faults bag), beyond what the
      motor can reach: rejected as a spike, so its block is no reversal (before 2026-11-29
      the block reversed and the load was forgotten: 6.0 kN off here).
    - first, last: 50 rad/s off at a block's first or last sample, under the spike check's
      bound, so accepted. The block's acceleration takes each end's speed as the median of
      three samples: from the end samples alone, 50 rad/s was 1,280 rad/s^2 of acceleration
      and 0.31 N m of inertia torque, which a jam explained (22.8 kN off here; on the
      sudden-jam bag a false count of 3, 6.5 % of rated load RMSE).
    - inside: standstill speed inside a block, accepted. The block's direction leaves out a
      wild sample inside it: the sample made the block a standstill, and the stroke started
      again (414 N off)."""
    scene = scene_from_mapping(downhole(duration_s=12.0))
    motor = simulate(scene).motor
    speed = np.abs(motor.speed_rad_s)
    heaviest = int(np.argmax(np.abs(motor.current_a) * (speed > 0.9 * speed.max())))
    params = EstimatorParams(actuator=scene.actuator)
    cells = np.floor((motor.stamp_s - motor.stamp_s[0]) / params.filter.block_duration_s)
    ends = np.flatnonzero(np.diff(cells)) + (0 if where == "last" else 1)
    block_end = int(ends[np.searchsorted(ends, heaviest)])
    at = {"against": heaviest, "inside": block_end + 15}.get(where, block_end)
    spiked = motor.speed_rad_s.copy()
    spiked[at] = {"against": -500.0 * np.sign(spiked[at]), "inside": 0.0}.get(
        where, spiked[at] + 50.0
    )
    results = []
    for samples in (motor, dataclasses.replace(motor, speed_rad_s=spiked)):
        estimator = HealthEstimator(params)
        states = estimator.process(samples) + estimator.finish()
        assert states[-1].samples_rejected == (where == "against" and len(results) == 1)
        results.append(states)
    clean, with_spike = ([s.axial_load_n for s in states] for states in results)
    assert abs(np.interp(motor.stamp_s[at], [s.stamp_s for s in results[0]], clean)) > 20e3
    assert np.max(np.abs(np.subtract(with_spike, clean))) < 0.005 * params.rated_load_n
    assert max(s.jam_probabilities[0] for s in results[1]) > 0.99
    assert min(s.jam_probabilities[0] for s in results[1]) > 0.5


def test_a_sensor_clock_jumping_by_decades_is_a_gap_not_a_jam() -> None:
    """A drive clock that switches from boot time to the epoch mid-run (+1.7e9 s): the
    estimator re-acquires the load after the gap, declares no jam and keeps tracking."""
    scene = scene_from_mapping(downhole())
    result = simulate(scene)
    jump_s = 1.7e9
    later = result.motor.stamp_s >= 8.0
    shifted = dataclasses.replace(
        result.motor, stamp_s=np.where(later, result.motor.stamp_s + jump_s, result.motor.stamp_s)
    )
    estimator = HealthEstimator(EstimatorParams(actuator=scene.actuator))
    states = estimator.process(shifted) + estimator.finish()
    assert all(s.jammed_rollers_most_likely == 0 for s in states)
    assert max(1.0 - s.jam_probabilities[0] for s in states) < 1e-3
    tail = [s for s in states if s.stamp_s > jump_s + 12.0]
    truth = np.interp(
        [s.stamp_s - jump_s for s in tail], result.truth.stamp_s, result.truth.axial_load_n
    )
    error = np.array([s.axial_load_n for s in tail]) - truth
    rated = EstimatorParams(actuator=scene.actuator).rated_load_n
    assert float(np.sqrt(np.mean(error**2))) < 0.01 * rated


@pytest.mark.parametrize("position", ["turning", "stuck"])
def test_a_clock_jump_adds_no_wear_of_its_own(position: str) -> None:
    """The drive clock jumps by +1.7e9 s mid-run. The block after the gap wears for at most
    filter.max_gap_s, or for as long as the positions say the motor turned; with the position
    sensor stuck, only the cap holds it (without it: 154.7 m of precision loss instead of
    about a micrometre, found by a mutation review)."""
    scene = scene_from_mapping(downhole(jams=[], duration_s=12.0))
    motor = simulate(scene).motor
    if position == "stuck":
        motor = dataclasses.replace(motor, position_rad=np.full(len(motor), 3.0))
    later = motor.stamp_s >= 8.0
    jumped = np.where(later, motor.stamp_s + 1.7e9, motor.stamp_s)
    params = EstimatorParams(actuator=scene.actuator)
    final_loss_m = []
    for stamps in (motor.stamp_s, jumped):
        estimator = HealthEstimator(params)
        states = estimator.process(dataclasses.replace(motor, stamp_s=stamps))
        final_loss_m.append((states + estimator.finish())[-1].precision_loss_m)
    assert final_loss_m[1] == pytest.approx(final_loss_m[0], rel=0.1)
    assert final_loss_m[0] > 0.0


@pytest.mark.parametrize("rate_hz", [1000.0, 4000.0])
def test_stamps_in_milliseconds_read_as_seconds_add_no_wear_of_their_own(rate_hz: float) -> None:
    """Every sample a gap of a second at 1 kHz, a hole of a quarter at 4 kHz: that much wear
    a sample, 500 to 1,000 times too much, saved for good by a node (found by two review
    sessions). The wear follows the motor's travel (its positions) where they say it turned
    for less than half the stamps' time. Two seconds of a stroke: every sample read in
    milliseconds is a block of its own (a run of 12 s took 30 s at 4 kHz)."""
    scene = scene_from_mapping(downhole(jams=[], duration_s=2.0, rate_hz=rate_hz))
    motor = simulate(scene).motor
    params = EstimatorParams(actuator=scene.actuator)
    final_loss_m = []
    for stamps in (motor.stamp_s, 1000.0 * motor.stamp_s):
        estimator = HealthEstimator(params)
        states = estimator.process(dataclasses.replace(motor, stamp_s=stamps))
        states += estimator.finish()
        final_loss_m.append(states[-1].precision_loss_m)
    assert 0.0 < final_loss_m[1] < 1.5 * final_loss_m[0]


def test_a_position_wrapped_into_one_turn_serves_as_well_as_the_turns() -> None:
    """A single-turn encoder. A wrapped position says little of the travel: taken from it,
    the wear and fatigue of a run were 61 % too small (found by the session's final review);
    positions that never pass two turns are not used for it. The carrier angle is taken from
    the positions unwrapped (inputs.SampleBlocker): taken from them as they were, the jammed
    roller's ripple was lost, 5 false jam declarations on the sudden-jam bag."""
    scene = scene_from_mapping(downhole(jams=[{"time_s": 6.0, "roller": 3}], duration_s=12.0))
    motor = simulate(scene).motor
    wrapped = np.mod(motor.position_rad + math.pi, 2.0 * math.pi) - math.pi
    params = EstimatorParams(actuator=scene.actuator)
    runs = []
    for position in (motor.position_rad, wrapped):
        estimator = HealthEstimator(params)
        states = estimator.process(dataclasses.replace(motor, position_rad=position))
        runs.append(states + estimator.finish())
    turns, single = runs
    assert [s.jammed_rollers_most_likely for s in single] == [
        s.jammed_rollers_most_likely for s in turns
    ]
    assert max(s.jammed_rollers_most_likely for s in turns) == 1
    np.testing.assert_allclose(
        [s.axial_load_n for s in single], [s.axial_load_n for s in turns], atol=1.0
    )
    np.testing.assert_allclose(
        (single[-1].precision_loss_m, single[-1].fatigue_damage),
        (turns[-1].precision_loss_m, turns[-1].fatigue_damage),
        rtol=0.02,
    )


def test_a_load_beyond_what_the_motor_can_drive_is_a_divergence() -> None:
    """A likeliest load of 200 times the rated load (seen with the UKF after a false count of
    three jammed rollers) is re-initialised whatever its NIS, and restarts from zero."""
    estimator = HealthEstimator(EstimatorParams(actuator=scene_from_mapping(downhole()).actuator))
    n = 2000
    t = np.arange(n) / 1000.0
    rng = np.random.default_rng(1)
    samples = MotorSamples(t, 6.0 + rng.normal(0, 0.05, n), np.full(n, 150.0), 150.0 * t)
    estimator.process(samples[:1000])
    for h in estimator._bank.hypotheses:
        h.filter.x[0] = 200.0 * estimator.params.rated_load_n
    states = estimator.process(samples[1000:])
    assert states[0].event == EstimateEvent.DIVERGENCE_RECOVERED
    assert all(abs(s.axial_load_n) < 10.0 * estimator.params.rated_load_n for s in states)


@pytest.mark.parametrize("rated_load_n", [30e3, 200e3])
def test_the_rated_load_of_the_diagnostics_does_not_change_the_estimates(
    rated_load_n: float,
) -> None:
    """It scaled the filter: set to 30 kN as an alarm level, the load RMSE of a run went from
    177 N to 303 N. Above the preset's largest load it raises only the divergence bound."""
    scene = scene_from_mapping(downhole(duration_s=8.0, jams=[{"time_s": 4.0, "roller": 2}]))
    samples = simulate(scene).motor
    default = EstimatorParams(actuator=scene.actuator)
    rated = dataclasses.replace(
        default, diagnostics=dataclasses.replace(default.diagnostics, rated_load_n=rated_load_n)
    )
    assert rated.rated_load_n == rated_load_n != default.rated_load_n
    assert rated.diverged_load_n == 10.0 * max(rated_load_n, default.rated_load_n)
    estimates = [HealthEstimator(p).process(samples) for p in (default, rated)]
    assert len(estimates[0]) > 100 and estimates[0] == estimates[1]


def test_a_clock_reset_starts_one_load_transition_not_one_per_block() -> None:
    """After the clock jumps back, the load model's stroke-start transition lasts its
    ``model.load_transition_s`` on the new time line, as after a direction change."""
    estimator = HealthEstimator(EstimatorParams(actuator=scene_from_mapping(downhole()).actuator))
    moving = Block(
        stamp_s=100.0,
        duration_s=0.04,
        samples=40,
        motor_torque_nm=1.0,
        motor_speed_rad_s=150.0,
        motor_acceleration_rad_s2=0.0,
        carrier_cos=0.0,
        carrier_sin=0.0,
        direction=1,
    )
    transition = [estimator._load_transition(moving, reverses=False)]
    transition += [
        estimator._load_transition(
            dataclasses.replace(moving, stamp_s=100.0 + 0.04 * i), reverses=False
        )
        for i in range(1, 50)
    ]
    reset = dataclasses.replace(moving, stamp_s=0.0, time_reset=True)
    transition.append(estimator._load_transition(reset, reverses=False))
    transition += [
        estimator._load_transition(dataclasses.replace(moving, stamp_s=0.04 * i), reverses=False)
        for i in range(1, 50)
    ]
    # load_transition_s = 1 s: the first 25 blocks of each time line.
    assert estimator.params.model.load_transition_s == 1.0
    assert transition == [i % 50 < 25 for i in range(100)]


def steady_samples(
    rng: np.random.Generator, t0: float, t1: float, speed_rad_s: float = 0.0
) -> MotorSamples:
    """Samples at 1 kHz from ``t0`` to ``t1`` of a motor standing still, or turning at
    ``speed_rad_s`` (noisy speed, current near 3 A)."""
    t = np.arange(t0, t1, 1e-3)
    speed = speed_rad_s + rng.normal(0.0, 0.2, len(t))
    return MotorSamples(t, 3.0 + rng.normal(0.0, 0.05, len(t)), speed, speed_rad_s * t)


def hole_reinitialisations(samples: MotorSamples, *, merge: bool) -> list[bool]:
    """``keep_load`` of each load re-initialisation while estimating ``samples``."""
    estimator = HealthEstimator(
        EstimatorParams(
            actuator=scene_from_mapping(downhole()).actuator,
            fidelity=Fidelity(merge_standstill_blocks=merge),
        )
    )
    calls: list[bool] = []
    reinitialise = estimator._bank.reinitialise_load

    def recorded(*, keep_load: bool = False) -> None:
        calls.append(keep_load)
        reinitialise(keep_load=keep_load)

    estimator._bank.reinitialise_load = recorded  # type: ignore[method-assign]
    estimator.process(samples)
    estimator.finish()
    return calls


def test_a_hole_inside_a_standstill_reacquires_the_load_merged_or_not() -> None:
    """A silence of several blocks at standstill forgets the load's derivatives whether the
    standstill's blocks are merged or not."""
    rng = np.random.default_rng(1)
    # a 0.3 s hole
    samples = MotorSamples.concatenate(
        [steady_samples(rng, 0.0, 1.0), steady_samples(rng, 1.3, 3.0)]
    )
    assert hole_reinitialisations(samples, merge=True) == [True]
    assert hole_reinitialisations(samples, merge=False) == [True]


def test_a_merged_standstill_estimate_stands_for_the_blocks_covering_its_duration() -> None:
    """With merged standstill blocks each estimate stands for the fewest whole blocks that
    cover fidelity.standstill_block_s (Fidelity's docstring: one update per 0.5 s): 13 blocks
    of 40 ms, 520 samples at 1 kHz, not 14. A mutation review found the count unguarded."""
    params = EstimatorParams(actuator=scene_from_mapping(downhole()).actuator)
    assert (params.fidelity.standstill_block_s, params.filter.block_duration_s) == (0.5, 0.04)
    estimator = HealthEstimator(params)
    states = estimator.process(steady_samples(np.random.default_rng(2), 0.0, 3.0))
    accepted = [0] + [state.samples_accepted for state in states]
    assert all(state.event is EstimateEvent.STANDSTILL for state in states)
    assert len(states) == 5 and set(np.diff(accepted)) == {520}


def test_after_a_hole_in_motion_jam_evidence_waits_while_the_load_is_found_again() -> None:
    """After a hole (more than HOLE_BLOCKS blocks without a sample) the blocks of the next
    REACQUIRE_S = 0.25 s are filtered without jam evidence (estimator.py: a load that moved
    inside the hole would look like a jam), as after a time reset. A mutation review found
    the hole's blind window unguarded."""
    estimator = HealthEstimator(EstimatorParams(actuator=scene_from_mapping(downhole()).actuator))
    weighed: list[tuple[float, bool]] = []
    step = estimator._bank.step

    def recorded(block: Block, **options: Any) -> Any:
        weighed.append((block.stamp_s, options["evidence"]))
        return step(block, **options)

    estimator._bank.step = recorded  # type: ignore[method-assign]
    rng = np.random.default_rng(4)
    hole_end = 1.3  # a 0.3 s hole
    estimator.process(
        MotorSamples.concatenate(
            [steady_samples(rng, 0.0, 1.0, 150.0), steady_samples(rng, hole_end, 2.0, 150.0)]
        )
    )
    after = [(stamp, evidence) for stamp, evidence in weighed if stamp > hole_end]
    blind_until = after[0][0] + REACQUIRE_S
    assert [evidence for _, evidence in after] == [stamp > blind_until for stamp, _ in after]
    assert sum(not evidence for _, evidence in after) == 7  # the first and 0.25 s after it


def test_maintenance_resets_the_count_and_only_what_was_replaced() -> None:
    """Jams only ever increase, except by maintenance: after "0 jammed" the next estimate is
    certain of 0; precision loss and fatigue damage start from zero only
    when their parts were replaced. Here the roller was not freed (the simulated jam goes on):
    its ripple in the next stroke says so, and count 1 comes back."""
    scene = scene_from_mapping(downhole(jams=[{"time_s": 4.0, "roller": 3}]))
    result = simulate(scene)
    params = EstimatorParams(actuator=scene.actuator)
    estimator = HealthEstimator(params)
    assert estimator.current_state() is None  # no estimate yet
    cut = int(np.searchsorted(result.motor.stamp_s, 12.0))  # standstill after two strokes
    before = estimator.process(result.motor[:cut])[-1]
    assert int(np.argmax(before.jam_probabilities)) == 1
    assert before.precision_loss_m > 0.0 and before.fatigue_damage > 0.0
    other = HealthEstimator(params)
    other.restore(estimator.snapshot())
    assert other.current_state() is None  # a restored state has no estimate
    for bad in (-1, 11, 1.0, True):  # a float or bool count would break the bank later
        expected = rf"jammed_rollers: must be an integer in \[0, 10\], got {bad!r}"
        with pytest.raises(ValueError, match=expected):
            estimator.reset_after_maintenance(
                bad,  # type: ignore[arg-type]
                reset_precision_loss=True,
                reset_fatigue_damage=True,
            )
        # The evidence's count as well: True spread the probabilities over every count, 2.5
        # raised an IndexError at the next block (found by a review session).
        with pytest.raises(ValueError, match=expected):
            other.assume_jam_onset(bad)  # type: ignore[arg-type]

    pending = estimator.reset_after_maintenance(
        0, reset_precision_loss=True, reset_fatigue_damage=False
    )
    # The samples fed before the maintenance are estimated before it.
    assert pending and all(int(np.argmax(s.jam_probabilities)) == 1 for s in pending)
    # The reset state at once, at the last estimate's stamp (for the node to publish).
    reset = estimator.current_state()
    assert reset is not None and reset.event == EstimateEvent.NONE
    last = pending[-1]
    assert (reset.stamp_s, reset.axial_load_n) == (last.stamp_s, last.axial_load_n)
    assert reset.jam_probabilities[0] == 1.0
    assert reset.precision_loss_m == reset.precision_loss_std_m == 0.0
    assert reset.fatigue_damage == last.fatigue_damage > 0.0
    assert reset.nis == 0.0  # the consistency window starts again
    after = estimator.process(result.motor[cut:]) + estimator.finish()
    first = after[0]
    assert first.jam_probabilities[0] > 1.0 - 1e-6  # the prior of a jam in 0.5 s: 1.4e-7
    assert first.precision_loss_m == first.precision_loss_std_m == 0.0
    assert first.fatigue_damage == before.fatigue_damage  # at standstill nothing accrues
    assert int(np.argmax(after[-1].jam_probabilities)) == 1  # the ripple: still jammed
    assert 0.0 < after[-1].precision_loss_m < before.precision_loss_m

    other.reset_after_maintenance(  # a numpy integer is a count like an int
        np.int64(0),  # type: ignore[arg-type]
        reset_precision_loss=False,
        reset_fatigue_damage=True,
    )
    kept = (other.process(result.motor[cut:]) + other.finish())[0]
    assert kept.precision_loss_m == before.precision_loss_m
    assert kept.fatigue_damage == kept.fatigue_damage_std == 0.0


def test_a_torque_constant_off_by_five_percent_is_in_the_load_uncertainty_when_stated() -> None:
    """The motor's torque constant 5 % larger in the estimator than in the simulated drive:
    every load reads about 5 % high, which no signal can show. Unstated
    (noise.torque_scale_error_rel 0), the load's uncertainty is the filter's alone and the
    errors lie far outside it; stated as 5 %, the load's variance carries (0.05 F)^2, the
    errors are inside it, and the precision loss's uncertainty grows with it."""
    scene = scene_from_mapping(downhole())
    result = simulate(scene)
    drive = scene.actuator.drive_train
    miscalibrated = dataclasses.replace(
        scene.actuator,
        drive_train=dataclasses.replace(
            drive, torque_constant_nm_per_a=1.05 * drive.torque_constant_nm_per_a
        ),
    )
    outcomes = {}
    for stated in (0.0, 0.05):
        base = params_for(scene, Fidelity())
        params = dataclasses.replace(
            base,
            actuator=miscalibrated,
            noise=dataclasses.replace(base.noise, torque_scale_error_rel=stated),
        )
        states, _ = chunked(params, result.motor)
        outcomes[stated] = (states, scored(states, result.truth, params))
    (exact_states, unstated), (stated_states, stated_metrics) = outcomes[0.0], outcomes[0.05]
    assert unstated.load_nees_mean > unstated.load_nees_interval[1]
    assert stated_metrics.load_nees_consistent
    # The same estimates, only their uncertainty differs, by (0.05 F)^2 in variance: each
    # hypothesis' (0.05 F_k)^2, weighed, which is (0.05 F)^2 of their mean up to 0.05^2 times
    # their spread (below 1e-7 of the variance on this run).
    for a, b in zip(exact_states, stated_states, strict=True):
        assert b.axial_load_n == a.axial_load_n
        expected = math.hypot(a.axial_load_std_n, 0.05 * a.axial_load_n)
        assert b.axial_load_std_n == pytest.approx(expected, rel=1e-6)
    assert stated_states[-1].precision_loss_std_m > exact_states[-1].precision_loss_std_m


# --- sample streams the node can deliver (adversarial fuzz, 2026-11) ---------------------------
#: The bundled example parameters (config/default.yaml's actuator: the downhole preset).
DEFAULT = EstimatorParams(actuator=scene_from_mapping(downhole()).actuator)


def _steady(stamps: np.ndarray, seed: int = 0, current_a: float = 2.0) -> MotorSamples:
    """Samples at ``stamps``: a noisy constant current at 300 rad/s."""
    rng = np.random.default_rng(seed)
    n = len(stamps)
    speed = 300.0 + rng.normal(0.0, 0.2, n)
    return MotorSamples(stamps, current_a + rng.normal(0.0, 0.05, n), speed, 300.0 * stamps)


def _fed_in_chunks(
    samples: MotorSamples, size: int, params: EstimatorParams = DEFAULT
) -> tuple[list[HealthState], HealthEstimator]:
    estimator = HealthEstimator(params)
    return fed_in_chunks(estimator.process, samples, size) + estimator.finish(), estimator


_MS = np.arange(3000) * 1e-3
#: Streams whose stamps jump: the case, the stamps, the time resets and the rejected samples
#: (TIME_BACKWARDS) expected.
JUMPING_STREAMS = {
    # Two garbage stamps far ahead, then the stream goes on: the second confirms the first,
    # and the good samples are followed as a time line jumped back.
    "two stamps far ahead": (np.r_[_MS[:1000], 1e9, 2e9, 1.0 + _MS], 1, 100),
    # One stamp far ahead, then the drive reboots (its clock restarts at 0).
    "a stamp far ahead, then a reboot": (np.r_[100.0 + _MS[:1000], 1e9, _MS], 1, 100),
    # Every stamp twice.
    "equal stamps": (np.repeat(_MS, 2), 0, 3000),
    # A stamp ahead by more than max_gap_s, three times: a duplicate neither confirms nor
    # contradicts the jump.
    "equal stamps after a jump": (np.r_[_MS[:1000], 5.0, 5.0, 5.0, 5.001 + _MS[:1000]], 0, 2),
}


@pytest.mark.parametrize("case", JUMPING_STREAMS)
def test_the_same_stream_gives_the_same_result_in_any_chunks(case: str) -> None:
    """The node feeds 1 to 20 samples at a time, replay thousands: the counters and every
    estimate must not depend on it. (A sample held back after a jump was judged again with
    each chunk: in chunks of 20 or 1, "two stamps far ahead" rejected every later sample with
    no time reset, and the duplicate accepted after a jump depended on the chunks.)"""
    stamps, time_resets, rejected = JUMPING_STREAMS[case]
    samples = _steady(stamps)
    whole, reference = _fed_in_chunks(samples, len(samples))
    counters = reference.counters
    assert counters.time_resets == time_resets
    assert counters.rejected_total == counters.rejected[RejectReason.TIME_BACKWARDS] == rejected
    assert counters.accepted + rejected == len(samples)
    for size in (1, 7, 20):
        states, estimator = _fed_in_chunks(samples, size)
        assert estimator.counters == counters, size
        assert states == whole, size


def test_a_reboot_with_jittering_stamps_is_followed_as_without_jitter() -> None:
    """Stamps jittering by 0.5 ms at 1 kHz (some a little before the one before), and the
    drive reboots: its clock restarts at 0. The new time line is followed once it covers
    filter.time_reset_after_s, as without jitter. (A stamp a little back on the new line
    started its count again: the reboot was never followed, every later sample rejected.)"""
    rng = np.random.default_rng(3)
    before = 1000.0 + _MS[:2000] + rng.normal(0.0, 0.5e-3, 2000)
    after = _MS + rng.normal(0.0, 0.5e-3, len(_MS))
    estimator = HealthEstimator(DEFAULT)
    estimator.process(_steady(before))
    rejected_before = estimator.counters.rejected_total
    states = estimator.process(_steady(after, seed=1)) + estimator.finish()
    assert estimator.counters.time_resets == 1
    first = next(s for s in states if s.event == EstimateEvent.TIME_RESET)
    # The first block of the new line: from the reset sample (0.1 s, a few samples more when
    # the first stamps jitter back) to the end of its 40 ms grid cell.
    reset_after = DEFAULT.filter.time_reset_after_s
    assert reset_after < first.stamp_s < reset_after + 0.01 + DEFAULT.filter.block_duration_s
    # After it, as before the reboot, only the stamps behind their predecessor are rejected.
    out_of_order = estimator.counters.rejected_total - rejected_before - 100
    assert out_of_order / (len(after) - 100) < 1.5 * rejected_before / len(before)


def test_a_time_reset_is_said_and_a_divergence_with_it_is_not_lost(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """An estimate stamped before the previous one says TIME_RESET (the evaluation splits the
    time lines there). Here the filter is gated on every block (two rollers said jammed, a
    current the load model cannot explain): it said DIVERGENCE_RECOVERED instead, since the
    gated blocks before the reset counted after it. Now the divergence tests start again at
    the reset; a divergence on the reset's own block is said by the next estimate. (Without
    the load bound: with it the counts that run off beyond 82.5 kN are dropped, and the
    filter is no longer gated on every block; and with the count held at the two told, no
    jam rate: more jams would run off through every count, gated on some blocks only.)"""
    unbounded = dataclasses.replace(
        DEFAULT,
        model=dataclasses.replace(DEFAULT.model, plausible_load_factor=0.0, jam_rate_per_h=0.0),
    )

    def estimates() -> tuple[list[HealthState], HealthEstimator]:
        estimator = HealthEstimator(unbounded)
        estimator.reset_after_maintenance(2, reset_precision_loss=False, reset_fatigue_damage=False)
        rng = np.random.default_rng(0)
        states = []
        for t0, n in ((100.0, 1000), (50.0, 500)):  # the clock jumps back by 51 s
            t = t0 + _MS[:n]
            current = -15.0 + rng.normal(0.0, 0.05, n)
            speed = 1099.0 + rng.normal(0.0, 0.2, n)
            states += estimator.process(MotorSamples(t, current, speed, 1099.0 * t))
        return states + estimator.finish(), estimator

    states, estimator = estimates()
    events = [s.event for s in states]
    back = [i for i in range(1, len(states)) if states[i].stamp_s < states[i - 1].stamp_s]
    resets = [i for i, event in enumerate(events) if event == EstimateEvent.TIME_RESET]
    assert back == resets and estimator.counters.time_resets == 1
    recovered = [i for i, event in enumerate(events) if event == EstimateEvent.DIVERGENCE_RECOVERED]
    assert recovered[0] < resets[0]  # gated before the reset too
    # The first recovery after the reset: its block is the GATED_BLOCKS_BEFORE_RESET-th gated.
    after = next(i for i in recovered if i > resets[0])
    assert after - resets[0] == GATED_BLOCKS_BEFORE_RESET - 1

    # A divergence on the reset's block (forced): said by the next estimate.
    original = HealthEstimator._diverged

    def diverged_at_the_reset(self: HealthEstimator, block: Block, step: Any) -> bool:
        return original(self, block, step) or block.time_reset

    monkeypatch.setattr(HealthEstimator, "_diverged", diverged_at_the_reset)
    states, _ = estimates()
    reset = next(i for i, s in enumerate(states) if s.event == EstimateEvent.TIME_RESET)
    assert states[reset + 1].event == EstimateEvent.DIVERGENCE_RECOVERED

    # Unsaid when the input ended at the reset's block, it is not said after a maintenance
    # (the first estimate after one said DIVERGENCE_RECOVERED).
    estimator = HealthEstimator(DEFAULT)
    estimator.process(_steady(100.0 + _MS[:1000]))
    ended = estimator.process(_steady(50.0 + _MS[:140], seed=1)) + estimator.finish()
    assert ended[-1].event == EstimateEvent.TIME_RESET
    monkeypatch.setattr(HealthEstimator, "_diverged", original)
    estimator.reset_after_maintenance(0, reset_precision_loss=False, reset_fatigue_damage=False)
    after = estimator.process(_steady(60.0 + _MS[:400], seed=2))
    assert after and all(s.event != EstimateEvent.DIVERGENCE_RECOVERED for s in after)


def test_maintenance_flags_must_be_bools() -> None:
    """The string "no" is true: reset_precision_loss="no" reset the precision loss."""
    estimator = HealthEstimator(DEFAULT)
    for name in ("reset_precision_loss", "reset_fatigue_damage"):
        for bad in ("no", 0, 1, None, np.bool_(False)):
            flags = {"reset_precision_loss": False, "reset_fatigue_damage": False, name: bad}
            with pytest.raises(ValueError, match=rf"^{name}: must be a bool, got {bad!r}"):
                estimator.reset_after_maintenance(0, **flags)  # type: ignore[arg-type]
    assert (
        estimator.reset_after_maintenance(0, reset_precision_loss=True, reset_fatigue_damage=False)
        == []
    )


def test_the_package_serves_a_library_user_as_its_docstring_shows() -> None:
    """From Python: ``from prsm_health.estimation import HealthEstimator`` failed (an empty
    package), ``load_params`` refused a str path with an AttributeError, and ``process(None)``
    said "'NoneType' object has no attribute 'stamp_s'"."""
    import prsm_health.estimation as estimation

    params = estimation.load_params(str(estimation.bundled_params_file()))
    estimator = estimation.HealthEstimator(params)
    states = estimator.process(_steady(_MS[:200])) + estimator.finish()
    assert states and all(isinstance(s, estimation.HealthState) for s in states)
    with pytest.raises(TypeError, match=r"must be a prsm_health\.signals\.MotorSamples .*NoneType"):
        estimator.process(None)  # type: ignore[arg-type]
