"""The per-roller table against the physics core it is built from.

The error bounds are the maxima measured over 600 random off-grid points per configuration
with ``bench/bench_roller_table.py`` (docs/scenes.md), rounded up; the tests draw fewer
points from the same distribution (axial load log-uniform over 0.1-1 x the preset's largest,
radial ratio uniform up to the table's largest, carrier angle uniform).
"""

from __future__ import annotations

import math
from dataclasses import fields

import numpy as np
import pytest

from prsm_health.physics.errors import DomainError, ParameterError
from prsm_health.physics.geometry import Misalignment
from prsm_health.physics.load_distribution import LoadingCase
from prsm_health.physics.presets import load_preset
from prsm_health.physics.roller_table import (
    RollerValues,
    TableGrid,
    roller_table,
    roller_values,
)

PRESET = load_preset("dong2022-downhole")
N_ROLLERS = PRESET.geometry.n_rollers
SPEED = 300.0 * math.pi / 30.0
ALIGNED = Misalignment()
TILTED = Misalignment.from_arcmin(2.0, 0.0)


def random_points(count: int, max_ratio: float, seed: int) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    largest = PRESET.largest_axial_load_n
    load = np.exp(rng.uniform(math.log(0.1 * largest), math.log(largest), count))
    ratio = rng.uniform(0.0, max_ratio, count)
    angle = rng.uniform(0.0, 2.0 * math.pi, count)
    return load, ratio, angle


def roller_angles(carrier: np.ndarray) -> np.ndarray:
    return carrier[:, np.newaxis] + 2.0 * math.pi * np.arange(N_ROLLERS) / N_ROLLERS


def worst(table_value: np.ndarray, exact_value: np.ndarray) -> float:
    return float(np.max(np.abs(table_value / exact_value - 1.0)))


@pytest.mark.parametrize(
    ("tilt", "case", "radial", "bounds"),
    [
        # healthy friction, one jammed roller (any), wear, peak force
        (ALIGNED, LoadingCase.SCREW_TENSION_NUT_COMPRESSION, True, (2e-4, 6e-3, 4e-3, 1.5e-3)),
        (ALIGNED, LoadingCase.BOTH_COMPRESSION, True, (2e-4, 6e-3, 4e-3, 1.5e-3)),
        (ALIGNED, LoadingCase.SCREW_TENSION_NUT_COMPRESSION, False, (5e-5, 1e-5, 3.5e-3, 1e-3)),
        (TILTED, LoadingCase.BOTH_COMPRESSION, False, (1e-3, 5e-3, 1.5e-3, 6e-3)),
    ],
    ids=["radial-case1", "radial-case2", "axial", "misaligned"],
)
def test_table_error_off_grid_is_within_the_measured_bound(
    tilt: Misalignment,
    case: LoadingCase,
    radial: bool,
    bounds: tuple[float, float, float, float],
) -> None:
    table = roller_table(PRESET, tilt, case, radial=radial)
    load, ratio, carrier = random_points(60, table.max_radial_ratio, seed=7)
    exact = roller_values(
        PRESET,
        load,
        radial_load_n=ratio * load,
        carrier_angle_rad=carrier,
        misalignment=tilt,
        case=case,
    )
    looked_up = table.lookup(load[:, None], ratio[:, None], roller_angles(carrier))
    friction, jammed_friction, wear, peak = bounds
    healthy = np.zeros(N_ROLLERS, dtype=bool)
    assert (
        worst(
            looked_up.friction_torque_nm(SPEED, healthy).sum(-1),
            exact.friction_torque_nm(SPEED, healthy).sum(-1),
        )
        < friction
    )
    for roller in range(N_ROLLERS):
        jam = np.arange(N_ROLLERS) == roller
        assert (
            worst(
                looked_up.friction_torque_nm(SPEED, jam).sum(-1),
                exact.friction_torque_nm(SPEED, jam).sum(-1),
            )
            < jammed_friction
        )
    assert worst(looked_up.wear_m_per_rad.sum(-1), exact.wear_m_per_rad.sum(-1)) < wear
    assert worst(looked_up.peak_contact_force_n.max(-1), exact.peak_contact_force_n.max(-1)) < peak


def test_table_reproduces_the_physics_at_its_nodes() -> None:
    grid = TableGrid(loads=4, ratios=3, angles_per_sector=4)
    table = roller_table(PRESET, ALIGNED, LoadingCase.BOTH_COMPRESSION, radial=True, grid=grid)
    load = table.load_grid_n[[1, 2, 3]]
    ratio = table.ratio_grid[[0, 1, 2]]
    # Solved carrier angles (0 and 1 step) and a mirrored one (3 steps of 2 pi / 40).
    carrier = np.array([0.0, 1.0, 3.0]) * 2.0 * math.pi / table.angles
    exact = roller_values(
        PRESET,
        load,
        radial_load_n=ratio * load,
        carrier_angle_rad=carrier,
        case=LoadingCase.BOTH_COMPRESSION,
    )
    looked_up = table.lookup(load[:, None], ratio[:, None], roller_angles(carrier))
    for f in fields(RollerValues):
        np.testing.assert_allclose(
            getattr(looked_up, f.name), getattr(exact, f.name), rtol=1e-9, atol=1e-300
        )


def test_rollers_relabel_when_the_carrier_turns_one_roller_spacing() -> None:
    """The premise of the table: one function of the roller angle serves every roller."""
    step = 2.0 * math.pi / N_ROLLERS
    for tilt in (ALIGNED, TILTED):
        here = roller_values(
            PRESET, 30_000.0, radial_load_n=6_000.0, carrier_angle_rad=0.3, misalignment=tilt
        )
        turned = roller_values(
            PRESET,
            30_000.0,
            radial_load_n=6_000.0,
            carrier_angle_rad=0.3 + step,
            misalignment=tilt,
        )
        np.testing.assert_allclose(
            np.roll(turned.rolling_torque_nm, 1), here.rolling_torque_nm, rtol=1e-9
        )
        np.testing.assert_allclose(
            np.roll(turned.peak_contact_force_n, 1), here.peak_contact_force_n, rtol=1e-9
        )


def test_aligned_rollers_mirror_about_the_radial_load() -> None:
    plus = roller_values(PRESET, 20_000.0, radial_load_n=8_000.0, carrier_angle_rad=0.2)
    minus = roller_values(PRESET, 20_000.0, radial_load_n=8_000.0, carrier_angle_rad=-0.2)
    # Roller i at 0.2 + 2 pi i / N mirrors roller (N - i) mod N at -0.2 - 2 pi i / N.
    mirrored = minus.rolling_torque_nm[(-np.arange(N_ROLLERS)) % N_ROLLERS]
    np.testing.assert_allclose(mirrored, plus.rolling_torque_nm, rtol=1e-8)


def test_below_the_grid_the_power_law_continues_to_zero() -> None:
    table = roller_table(PRESET, ALIGNED, LoadingCase.SCREW_TENSION_NUT_COMPRESSION, radial=False)
    smallest = table.load_grid_n[0]
    at_grid = table.lookup(smallest, 0.0, 0.0)
    half = table.lookup(smallest / 2.0, 0.0, 0.0)
    zero = table.lookup(0.0, 0.0, 0.0)
    assert half.rolling_torque_nm == pytest.approx(at_grid.rolling_torque_nm * 0.5 ** (4 / 3))
    assert half.jammed_torque_nm == pytest.approx(at_grid.jammed_torque_nm * 0.5)
    for f in fields(RollerValues):
        assert getattr(zero, f.name) == 0.0


def test_lookup_refuses_inputs_outside_the_table() -> None:
    radial = roller_table(PRESET, ALIGNED, LoadingCase.SCREW_TENSION_NUT_COMPRESSION, radial=True)
    axial = roller_table(PRESET, ALIGNED, LoadingCase.SCREW_TENSION_NUT_COMPRESSION, radial=False)
    with pytest.raises(DomainError, match="axial_load_n"):
        radial.lookup(radial.max_axial_load_n * 1.01, 0.0, 0.0)
    with pytest.raises(DomainError, match="radial_ratio"):
        radial.lookup(10_000.0, radial.max_radial_ratio * 1.01, 0.0)
    with pytest.raises(DomainError, match="radial_ratio"):
        axial.lookup(10_000.0, 0.1, 0.0)
    with pytest.raises(ParameterError, match="axial_load_n"):
        radial.lookup(-1.0, 0.0, 0.0)
    with pytest.raises(ParameterError, match="angle_rad"):
        radial.lookup(1.0, 0.0, math.nan)


def test_grid_is_validated_by_field() -> None:
    with pytest.raises(ParameterError, match=r"grid\.ratio_max_fraction"):
        TableGrid(ratio_max_fraction=1.2)
    with pytest.raises(ParameterError, match=r"grid\.loads: must be an integer >= 2, got 1"):
        TableGrid(loads=1)
    with pytest.raises(ParameterError, match=r"grid\.ratios: must be an integer >= 2, got 2.5"):
        TableGrid(ratios=2.5)  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match=r"grid\.load_min_fraction: must be a finite number"):
        TableGrid(load_min_fraction=math.nan)
    with pytest.raises(ParameterError, match=r"grid\.load_max_factor: must be > load_min_fraction"):
        TableGrid(load_min_fraction=0.5, load_max_factor=0.1)
