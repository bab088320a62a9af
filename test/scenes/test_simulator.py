"""The truth simulator: determinism, chunking, physics consistency and truth invariants."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import fields

import numpy as np
import pytest

from prsm_health.actuator import load_torque_nm
from prsm_health.physics.errors import ParameterError
from prsm_health.physics.geometry import Misalignment
from prsm_health.physics.load_distribution import LoadingCase
from prsm_health.physics.model import OperatingPoint, evaluate
from prsm_health.physics.roller_table import roller_values
from prsm_health.scenes.profiles import (
    ConstantProfile,
    ConstantRadial,
    DownholeCycle,
    SineProfile,
    profile_from_mapping,
)
from prsm_health.scenes.scene import Jam, Scene, load_scene, scene_from_mapping
from prsm_health.scenes.sensors import Sensors
from prsm_health.scenes.simulator import SimulationChunk, Simulator, simulate
from prsm_health.signals import TruthSamples

IDEAL_SENSORS = Sensors(
    current_noise_std_a=0.0,
    current_quantum_a=0.0,
    encoder_counts_per_rev=0,
    speed_filter_hz=0.0,
    speed_noise_std_rad_s=0.0,
    speed_quantum_rad_s=0.0,
    stamp_jitter_s=0.0,
    receive_latency_s=0.0,
    receive_jitter_s=0.0,
)

#: A short scene that exercises everything that carries state between chunks: strokes and
#: standstill (stiction), load noise, radial load, a jam, sensor noise and every fault kind.
BUSY = {
    "name": "busy",
    "actuator": {"preset": "dong2022-downhole", "wear_acceleration": 1.0e5},
    "duration_s": 3.0,
    "seed": 11,
    "profile": {
        "type": "downhole_cycle",
        "stroke_m": 0.012,
        "speed_rpm": [300.0, 500.0],
        "traction_load_n": [20000.0, 40000.0],
        "support_s": 0.2,
        "accel_s": 0.1,
        "load_ramp_s": 0.15,
    },
    "radial_load": {"type": "wall", "min_n": 1000.0, "max_n": 6000.0, "period_s": 1.0},
    "load_noise": {"relative_std": 0.02, "bandwidth_hz": 2.0},
    "jams": [{"time_s": 1.1, "roller": 3}],
    "sensor_faults": {
        "dropouts": [{"start_s": 0.5, "duration_s": 0.02}],
        "nonfinite": [{"time_s": 0.7, "field": "all", "value": float("nan"), "samples": 2}],
        "spikes": [{"time_s": 0.9, "field": "current_a", "value": 30.0}],
        "stuck": [{"start_s": 1.4, "duration_s": 0.3, "field": "speed_rad_s"}],
        "time_jumps": [{"time_s": 2.0, "jump_s": -0.3}],
    },
    "truth_rate_hz": 500.0,
}


def assert_runs_equal(first: SimulationChunk, second: SimulationChunk) -> None:
    for f in fields(first.motor):
        np.testing.assert_array_equal(getattr(first.motor, f.name), getattr(second.motor, f.name))
    np.testing.assert_array_equal(first.receive_time_s, second.receive_time_s)
    for f in fields(TruthSamples):
        np.testing.assert_array_equal(getattr(first.truth, f.name), getattr(second.truth, f.name))


def test_the_same_scene_and_seed_give_identical_runs_and_other_seeds_differ() -> None:
    scene = scene_from_mapping(BUSY)
    first, second = simulate(scene), simulate(scene)
    assert_runs_equal(first, second)
    other = simulate(dataclasses.replace(scene, seed=12))
    assert not np.array_equal(first.truth.axial_load_n, other.truth.axial_load_n)
    assert not np.array_equal(first.motor.current_a, other.motor.current_a, equal_nan=True)


def test_results_do_not_depend_on_the_chunk_size() -> None:
    scene = scene_from_mapping(BUSY)
    whole = simulate(scene, chunk_samples=scene.samples)
    for chunk in (1000, 333, 7):
        assert_runs_equal(whole, simulate(scene, chunk_samples=chunk))


def steady_scene(*, jams: tuple[Jam, ...], radial_n: float, tilt: Misalignment) -> Scene:
    base = scene_from_mapping(
        {
            "name": "steady",
            "actuator": {"preset": "dong2022-downhole"},
            "duration_s": 0.25,
            "profile": {"type": "constant", "speed_rpm": -300.0, "axial_load_n": -20000.0},
            "truth_rate_hz": 100.0,
        }
    )
    return dataclasses.replace(
        base,
        actuator=dataclasses.replace(base.actuator, misalignment=tilt),
        actuator_yaml=None,  # no longer the file's section
        radial_load=ConstantRadial(value_n=radial_n),
        jams=jams,
        sensors=IDEAL_SENSORS,
    )


def torque_balance(scene: Scene, truth: TruthSamples, k: int) -> tuple[float, float]:
    """Friction and motor current from the physics core at truth sample k (steady speed)."""
    actuator = scene.actuator
    jammed = int(truth.jammed_rollers[k])
    assert bool(np.all(truth.roller_jammed[k, :jammed]))  # the first rollers, as evaluate's
    result = evaluate(
        actuator.preset,
        OperatingPoint(
            axial_load_n=abs(float(truth.axial_load_n[k])),
            radial_load_n=float(truth.radial_load_n[k]),
            screw_speed_rad_s=float(truth.screw_speed_rad_s[k]),
            jammed_rollers=jammed,
            misalignment=actuator.misalignment,
            case=LoadingCase(int(truth.loading_case[k])),
            carrier_angle_rad=float(truth.carrier_angle_rad[k]),
        ),
    )
    speed = float(truth.screw_speed_rad_s[k])
    friction = math.copysign(float(result.friction.total_nm), speed)
    screw_torque = float(load_torque_nm(actuator.preset, truth.axial_load_n[k])) + friction
    return friction, float(actuator.drive_train.current_a(screw_torque, speed))


@pytest.mark.parametrize(
    ("radial_n", "tilt"),
    [(5000.0, Misalignment()), (0.0, Misalignment.from_arcmin(2.0, 0.0))],
    ids=["radial", "misaligned"],
)
def test_exact_mode_current_is_the_physics_core_torque_balance(
    radial_n: float, tilt: Misalignment
) -> None:
    scene = steady_scene(jams=(Jam(time_s=0.12, roller=1),), radial_n=radial_n, tilt=tilt)
    run = simulate(scene, exact=True)
    truth = run.truth
    assert int(truth.jammed_rollers[0]) == 0 and int(truth.jammed_rollers[-1]) == 1
    for k in range(len(truth)):
        friction, current = torque_balance(scene, truth, k)
        assert float(truth.friction_torque_nm[k]) == pytest.approx(friction, rel=1e-6)
        # Ideal sensors: the published current is the simulated one (same sample stamps).
        at = int(np.flatnonzero(run.motor.stamp_s == truth.stamp_s[k])[0])
        assert float(run.motor.current_a[at]) == pytest.approx(current, rel=1e-6)


def test_exact_mode_agrees_across_chunk_sizes_to_the_solver_tolerance() -> None:
    scene = steady_scene(jams=(Jam(time_s=0.12, roller=1),), radial_n=5000.0, tilt=Misalignment())
    whole = simulate(scene, exact=True).truth
    chunked = simulate(scene, exact=True, chunk_samples=37).truth
    np.testing.assert_allclose(chunked.friction_torque_nm, whole.friction_torque_nm, rtol=1e-9)
    np.testing.assert_allclose(chunked.precision_loss_m, whole.precision_loss_m, rtol=1e-9)


def test_table_mode_friction_is_within_the_table_error() -> None:
    """Bounds: test/physics/test_roller_table.py (aligned radial: 2e-4 healthy, 6e-3 jammed)."""
    scene = steady_scene(jams=(Jam(time_s=0.12, roller=1),), radial_n=5000.0, tilt=Misalignment())
    truth = simulate(scene).truth
    for k in range(len(truth)):
        friction, _ = torque_balance(scene, truth, k)
        bound = 6e-3 if truth.jammed_rollers[k] else 2e-4
        assert float(truth.friction_torque_nm[k]) == pytest.approx(friction, rel=bound)


@pytest.fixture(scope="module")
def sudden_jam() -> SimulationChunk:
    return simulate(load_scene("sudden-jam"))


@pytest.fixture(scope="module")
def hold() -> tuple[Scene, SimulationChunk]:
    scene = load_scene("stationary-hold")
    return scene, simulate(scene)


def test_jams_loss_and_damage_never_decrease(sudden_jam: SimulationChunk) -> None:
    truth = sudden_jam.truth
    jammed = truth.jammed_rollers
    assert np.all(np.diff(jammed) >= 0)
    assert (jammed[0], jammed[-1]) == (0, 2)
    # Once jammed, a roller stays jammed.
    assert np.all(np.diff(truth.roller_jammed.astype(int), axis=0) >= 0)
    assert np.all(np.diff(truth.precision_loss_m) >= 0.0)
    assert np.all(np.diff(truth.fatigue_damage) >= 0.0)
    assert truth.precision_loss_m[-1] > 0.0


def test_jams_happen_when_the_scene_says(sudden_jam: SimulationChunk) -> None:
    truth = sudden_jam.truth
    first = truth.stamp_s[np.argmax(truth.jammed_rollers >= 1)]
    second = truth.stamp_s[np.argmax(truth.jammed_rollers >= 2)]
    assert first == pytest.approx(4.5) and second == pytest.approx(25.0)
    assert np.flatnonzero(truth.roller_jammed[-1]).tolist() == [3, 8]


def test_friction_opposes_the_motion(sudden_jam: SimulationChunk) -> None:
    truth = sudden_jam.truth
    moving = truth.screw_speed_rad_s != 0.0
    loaded = moving & (np.abs(truth.axial_load_n) > 1000.0)
    # > 0 resists positive rotation, like the axial load: friction has the speed's sign.
    assert np.all(
        np.sign(truth.friction_torque_nm[loaded]) == np.sign(truth.screw_speed_rad_s[loaded])
    )
    # The downhole traction load resists every stroke.
    assert np.all(np.sign(truth.axial_load_n[loaded]) == np.sign(truth.screw_speed_rad_s[loaded]))


def test_back_driving_brakes_with_the_load(hold: tuple[Scene, SimulationChunk]) -> None:
    scene, run = hold
    truth = run.truth
    returning = (truth.screw_speed_rad_s < -20.0) & (truth.axial_load_n > 10_000.0)
    assert returning.sum() > 100
    # The load drives the motion; friction still resists it; the motor brakes.
    assert np.all(truth.friction_torque_nm[returning] < 0.0)
    screw_torque = (
        load_torque_nm(scene.actuator.preset, truth.axial_load_n) + truth.friction_torque_nm
    )
    assert np.all(screw_torque[returning] > 0.0)
    stamps = np.isin(run.motor.stamp_s.round(6), truth.stamp_s[returning].round(6))
    assert np.all(run.motor.current_a[stamps] > 0.0)
    # Braking: the gearbox loss helps, so the motor needs less than T / (G k_t).
    drive = scene.actuator.drive_train
    k = int(np.flatnonzero(returning)[0])
    lossless = screw_torque[k] / (drive.gear_ratio * drive.torque_constant_nm_per_a)
    assert 0.0 < float(drive.current_a(screw_torque[k], truth.screw_speed_rad_s[k])) < lossless


def test_stiction_keeps_the_friction_within_the_breakaway_band(
    hold: tuple[Scene, SimulationChunk],
) -> None:
    scene, run = hold
    truth = run.truth
    at_rest = (truth.screw_speed_rad_s == 0.0) & (np.abs(truth.axial_load_n) > 1000.0)
    assert at_rest.sum() > 1000
    rows = np.flatnonzero(at_rest)[::97]
    actuator = scene.actuator
    breakaway = np.array(
        [
            roller_values(
                actuator.preset,
                abs(float(truth.axial_load_n[k])),
                radial_load_n=float(truth.radial_load_n[k]),
                carrier_angle_rad=float(truth.carrier_angle_rad[k]),
                case=LoadingCase(int(truth.loading_case[k])),
            )
            .friction_torque_nm(0.0, truth.roller_jammed[k])
            .sum()
            for k in rows
        ]
    )
    held = np.abs(truth.friction_torque_nm[rows])
    assert np.all(held <= breakaway * (1.0 + 2e-4))  # the table's healthy-friction error
    # While the held load rises the friction helps to hold it, at the edge of its band.
    assert np.max(held / breakaway) > 0.99


def test_speed_loop_reaches_rest_and_the_reference_speed() -> None:
    scene = load_scene("nominal-downhole")
    simulator = Simulator(scene)
    run = simulate(scene)
    truth = run.truth
    reference = simulator.reference(truth.stamp_s).speed_rad_s
    # 0.2 s into a plateau of the reference the 25 Hz loop has settled (e^-31).
    earlier = simulator.reference(truth.stamp_s - 0.2).speed_rad_s
    plateau = (reference != 0.0) & (reference == earlier)
    assert plateau.sum() > 2000
    np.testing.assert_allclose(truth.screw_speed_rad_s[plateau], reference[plateau], rtol=1e-9)
    assert np.sum(truth.screw_speed_rad_s == 0.0) > 1000
    assert isinstance(scene.profile, DownholeCycle)
    rpm = np.abs(truth.screw_speed_rad_s).max() * 30.0 / math.pi
    assert 250.0 <= rpm <= 450.0


def test_a_sine_load_resists_the_motion_or_keeps_its_sign() -> None:
    """By default the sine stroke's load changes sign with the reference speed (it resists
    the motion); with ``resisting: false`` it is the same load throughout, as gravity: it
    resists the forward strokes and drives the reverse ones. Anything but a bool is refused."""
    time_s = np.linspace(0.0, 8.0, 801)
    resisting = SineProfile(axial_load_n=10_000.0).reference(time_s)
    constant = SineProfile(axial_load_n=10_000.0, resisting=False).reference(time_s)
    assert set(resisting.direction.tolist()) == {-1, 1}
    np.testing.assert_array_equal(resisting.axial_load_n, 10_000.0 * resisting.direction)
    assert constant.axial_load_n.shape == time_s.shape  # an array, not a broadcast scalar
    assert np.all(constant.axial_load_n == 10_000.0)
    np.testing.assert_array_equal(constant.speed_rad_s, resisting.speed_rad_s)
    with pytest.raises(ParameterError, match=r"resisting: must be true or false, got 'no'"):
        profile_from_mapping({"type": "sine", "resisting": "no"})


def test_constant_profile_starts_steady() -> None:
    scene = steady_scene(jams=(), radial_n=0.0, tilt=Misalignment())
    assert isinstance(scene.profile, ConstantProfile)
    truth = simulate(scene).truth
    np.testing.assert_allclose(truth.screw_speed_rad_s, -10.0 * math.pi, rtol=1e-12)
