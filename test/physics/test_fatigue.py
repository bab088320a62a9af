"""Fatigue life of paper 000 eq. 29 and Palmgren-Miner damage."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.typing import NDArray

from prsm_health.physics.errors import ParameterError
from prsm_health.physics.fatigue import (
    DutyBlock,
    damage_rate_per_s,
    fatigue_life_h,
    miner_damage,
    stress_cycles_per_screw_revolution,
)
from prsm_health.physics.hertz import thread_contacts
from prsm_health.physics.load_distribution import solve_load_distribution
from prsm_health.physics.parameters import FatigueParameters
from prsm_health.physics.presets import load_preset

PRESET = load_preset("dong2022-downhole")
GEOMETRY = PRESET.geometry
FATIGUE = PRESET.fatigue
RPM = 2 * math.pi / 60


def synthetic_loads(axial_load_n: float) -> NDArray[np.float64]:
    """Forces falling linearly to half from the loaded end, summing to the axial load."""
    shape = np.linspace(2.0, 1.0, GEOMETRY.n_threads)
    per_roller = np.broadcast_to(shape, (GEOMETRY.n_rollers, GEOMETRY.n_threads))
    scale = axial_load_n / (per_roller.sum() * GEOMETRY.axial_projection)
    return np.asarray(scale * per_roller, dtype=np.float64)


def test_stress_cycles_per_revolution_of_000_geometry() -> None:
    # d_s / d_r = 3: kappa (kappa + 2) / (kappa + 1) = 15 / 4.
    assert stress_cycles_per_screw_revolution(GEOMETRY) == pytest.approx(3.75)


def test_life_is_000_eq_29_in_hours_for_rpm() -> None:
    loads = synthetic_loads(20e3)
    p_max = float(thread_contacts(GEOMETRY).screw_roller.max_pressure_pa(loads.max()))
    n_s = (FATIGUE.reference_pressure_pa / p_max) ** FATIGUE.stress_exponent * 2.5e8
    kappa, rpm = 3.0, 300.0
    expected_h = n_s * (kappa + 1) / (60 * rpm * kappa * (kappa + 2))
    assert float(fatigue_life_h(GEOMETRY, FATIGUE, loads, rpm * RPM)) == pytest.approx(
        expected_h, rel=1e-12
    )


def test_life_falls_as_pressure_to_the_minus_stress_exponent() -> None:
    base = synthetic_loads(20e3)
    scales = np.geomspace(0.5, 3.0, 7)
    loads = scales[:, None, None] * base
    lives = fatigue_life_h(GEOMETRY, FATIGUE, loads, 300 * RPM)
    p_max = thread_contacts(GEOMETRY).screw_roller.max_pressure_pa(loads.max(axis=(1, 2)))
    slope_pressure = np.polyfit(np.log(p_max), np.log(lives), 1)[0]
    slope_load = np.polyfit(np.log(scales), np.log(lives), 1)[0]
    assert slope_pressure == pytest.approx(-FATIGUE.stress_exponent, rel=1e-9)
    assert slope_load == pytest.approx(-FATIGUE.stress_exponent / 3, rel=1e-9)


def test_calibration_point_of_000_case_1() -> None:
    """000 Fig. 20: F_a 20 kN, F_r 4 kN, 300 rpm -> about 7,000 h (our p_ref calibration)."""
    loads = solve_load_distribution(GEOMETRY, 20e3, radial_load_n=4e3).screw_roller_n
    assert float(fatigue_life_h(GEOMETRY, FATIGUE, loads, 300 * RPM)) == pytest.approx(
        7000.0, rel=0.03
    )


def test_zero_speed_or_load_gives_infinite_life_and_zero_damage() -> None:
    loads = np.stack([synthetic_loads(20e3), np.zeros((GEOMETRY.n_rollers, GEOMETRY.n_threads))])
    speeds = np.array([[0.0], [30.0]])  # (2, 1) against two load cases -> (2, 2)
    lives = fatigue_life_h(GEOMETRY, FATIGUE, loads, speeds)
    rates = damage_rate_per_s(GEOMETRY, FATIGUE, loads, speeds)
    assert lives.shape == rates.shape == (2, 2)
    assert np.isinf(lives[0, 0]) and np.isinf(lives[0, 1]) and np.isinf(lives[1, 1])
    assert np.isfinite(lives[1, 0]) and lives[1, 0] > 0
    np.testing.assert_array_equal(rates == 0.0, np.isinf(lives))
    assert not np.isnan(lives).any()


def test_direction_of_rotation_does_not_matter() -> None:
    loads = synthetic_loads(30e3)
    assert float(fatigue_life_h(GEOMETRY, FATIGUE, loads, -20.0)) == float(
        fatigue_life_h(GEOMETRY, FATIGUE, loads, 20.0)
    )


def test_miner_one_life_is_damage_one_and_blocks_add() -> None:
    loads, speed = synthetic_loads(25e3), 200 * RPM
    life_s = float(fatigue_life_h(GEOMETRY, FATIGUE, loads, speed)) * 3600.0
    assert miner_damage(GEOMETRY, FATIGUE, [DutyBlock(life_s, loads, speed)]) == pytest.approx(1.0)
    other = DutyBlock(1.0e6, synthetic_loads(40e3), 500 * RPM)
    first = DutyBlock(0.3 * life_s, loads, speed)
    assert miner_damage(GEOMETRY, FATIGUE, [first, other]) == pytest.approx(
        0.3 + miner_damage(GEOMETRY, FATIGUE, [other]), rel=1e-12
    )
    assert miner_damage(GEOMETRY, FATIGUE, []) == 0.0


@settings(max_examples=40, deadline=None)
@given(st.floats(1.0, 1e7), st.floats(0.0, 1.0), st.floats(1e3, 6e4), st.floats(-80.0, 80.0))
def test_splitting_a_block_does_not_change_damage(
    duration: float, split: float, axial: float, speed: float
) -> None:
    loads = synthetic_loads(axial)
    whole = miner_damage(GEOMETRY, FATIGUE, [DutyBlock(duration, loads, speed)])
    parts = miner_damage(
        GEOMETRY,
        FATIGUE,
        [
            DutyBlock(split * duration, loads, speed),
            DutyBlock((1 - split) * duration, loads, speed),
        ],
    )
    assert parts == pytest.approx(whole, rel=1e-12, abs=1e-300)


def test_fatigue_rejects_bad_inputs() -> None:
    loads = synthetic_loads(10e3)
    with pytest.raises(ParameterError, match="screw_roller_n"):
        fatigue_life_h(GEOMETRY, FATIGUE, loads[:-1], 10.0)
    with pytest.raises(ParameterError, match="screw_roller_n"):
        fatigue_life_h(GEOMETRY, FATIGUE, -loads, 10.0)
    with pytest.raises(ParameterError, match="screw_speed_rad_s"):
        fatigue_life_h(GEOMETRY, FATIGUE, loads, math.nan)
    with pytest.raises(ParameterError, match="screw_speed_rad_s"):
        fatigue_life_h(GEOMETRY, FATIGUE, np.stack([loads, loads]), np.ones(3))
    with pytest.raises(ParameterError, match="duration_s"):
        miner_damage(GEOMETRY, FATIGUE, [DutyBlock(-1.0, loads, 10.0)])
    with pytest.raises(ParameterError, match="screw_roller_n"):
        miner_damage(
            GEOMETRY, FATIGUE, [DutyBlock(1.0, loads, 10.0), DutyBlock(1.0, loads[1:], 1.0)]
        )
    with pytest.raises(ParameterError, match=r"fatigue\.reference_pressure_pa"):
        FatigueParameters(reference_pressure_pa=-1.0)
