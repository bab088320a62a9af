"""Load distribution: paper numbers, equilibrium, loading cases, radial load, robustness."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from prsm_health.physics import load_distribution
from prsm_health.physics.errors import ConvergenceError, DomainError, ParameterError
from prsm_health.physics.geometry import Misalignment
from prsm_health.physics.load_distribution import (
    NEGLIGIBLE_LOAD_N,
    LoadingCase,
    radial_capacity_ratio,
    solve_load_distribution,
)
from prsm_health.physics.meshing import meshing
from prsm_health.physics.presets import PRESET_NAMES, load_preset

M004 = load_preset("meng2022-misalignment").geometry
D000 = load_preset("dong2022-downhole").geometry


def test_004_peak_screw_roller_force_at_50kn() -> None:
    """004 section 3.2: 585.5 N peak (aligned); the reproduction note finds ~613 N (+-6 %)."""
    result = solve_load_distribution(M004, 50_000.0)
    assert result.screw_roller_n.max() == pytest.approx(585.5, rel=0.06)
    # Our own figures (docs/physics.md), pinned: within the paper's 6 % a roller segment of
    # 2p (607.6 N) or the torsion error's sign reversed passed unseen (a mutation review).
    assert result.screw_roller_n.max() == pytest.approx(613.14, rel=1e-4)
    twisted = solve_load_distribution(M004, 50_000.0, elastic_errors=True)
    assert twisted.screw_roller_n.max() == pytest.approx(641.93, rel=1e-4)


@pytest.mark.parametrize(
    ("tilt_arcmin", "paper_peak_n"), [((1.0, 0.0), 777.2), ((1.0, 1.0), 865.8)]
)
def test_004_misalignment_raises_the_peak_force_as_published(
    tilt_arcmin: tuple[float, float], paper_peak_n: float
) -> None:
    """004 section 3.2: 1' about x: 585.5 -> 777.2 N; 1' about x and y: 865.8 N (at 50 kN)."""
    mesh = meshing(M004, Misalignment.from_arcmin(*tilt_arcmin))
    result = solve_load_distribution(
        M004,
        50_000.0,
        clearance_screw_roller_m=mesh.axial_clearance_screw_roller_m,
        clearance_roller_nut_m=mesh.axial_clearance_roller_nut_m,
    )
    assert result.screw_roller_n.max() == pytest.approx(paper_peak_n, rel=0.06)
    aligned = solve_load_distribution(M004, 50_000.0)
    # "significantly change" at the screw-roller interface, "slightly" at the roller-nut one.
    sr_rise = result.screw_roller_n.max() / aligned.screw_roller_n.max()
    rn_rise = result.roller_nut_n.max() / aligned.roller_nut_n.max()
    assert sr_rise > 1.2 and rn_rise < sr_rise


@pytest.mark.parametrize("case", list(LoadingCase))
@pytest.mark.parametrize("elastic_errors", [False, True])
def test_axial_equilibrium_to_1e_9(case: LoadingCase, elastic_errors: bool) -> None:
    loads = np.array([1_000.0, 20_000.0, 55_000.0])
    result = solve_load_distribution(D000, loads, case=case, elastic_errors=elastic_errors)
    c = D000.axial_projection
    for axial, q_s, q_n in zip(loads, result.screw_roller_n, result.roller_nut_n, strict=True):
        assert q_s.sum() * c == pytest.approx(axial, rel=1e-9)
        assert q_n.sum() * c == pytest.approx(axial, rel=1e-9)


def test_radial_equilibrium_to_1e_9_at_any_carrier_angle() -> None:
    theta = np.linspace(0.0, 2.0 * math.pi, 7)
    result = solve_load_distribution(
        D000, 20_000.0, radial_load_n=4_000.0, radial_load_angle_rad=0.3, carrier_angle_rad=theta
    )
    phi = theta[:, None] + np.asarray(D000.roller_angles_rad)[None, :]
    per_roller = result.screw_roller_n.sum(axis=-1) * D000.radial_projection
    force = np.stack(((per_roller * np.cos(phi)).sum(-1), (per_roller * np.sin(phi)).sum(-1)), -1)
    expected = 4_000.0 * np.array([math.cos(0.3), math.sin(0.3)])
    assert np.allclose(force, expected, rtol=0, atol=4_000.0 * 1e-9)
    axial = result.screw_roller_n.sum(axis=(-1, -2)) * D000.axial_projection
    assert np.allclose(axial, 20_000.0, rtol=1e-9)


def test_000_case_1_loads_fall_monotonically_from_the_loaded_end() -> None:
    result = solve_load_distribution(D000, 20_000.0, elastic_errors=True)
    assert np.all(np.diff(result.screw_roller_n, axis=-1) < 0.0)
    assert np.all(np.diff(result.roller_nut_n, axis=-1) < 0.0)


def test_000_case_2_differs_and_unloads_the_first_thread_relative_to_case_1() -> None:
    case1 = solve_load_distribution(D000, 30_000.0, case=LoadingCase.SCREW_TENSION_NUT_COMPRESSION)
    case2 = solve_load_distribution(D000, 30_000.0, case=LoadingCase.BOTH_COMPRESSION)
    # Compression-compression moves load from the first threads towards the far end.
    assert case2.screw_roller_n[0, 0] < case1.screw_roller_n[0, 0]
    assert case2.roller_nut_n[0, -1] > case1.roller_nut_n[0, -1]


def test_radial_load_makes_thread_loads_periodic_in_the_position_angle() -> None:
    """000 Fig. 12: with F_r = 4 kN a thread's load varies with the roller position angle."""
    period = 2.0 * math.pi / D000.n_rollers
    theta = np.linspace(0.0, 2.0 * math.pi, 41)
    result = solve_load_distribution(D000, 20_000.0, radial_load_n=4_000.0, carrier_angle_rad=theta)
    first_thread = result.screw_roller_n[:, 0, 0]
    assert first_thread.max() / first_thread.min() > 1.5
    assert first_thread[0] == pytest.approx(first_thread[-1], rel=1e-9)  # one carrier turn
    shifted = solve_load_distribution(
        D000, 20_000.0, radial_load_n=4_000.0, carrier_angle_rad=theta + period
    )
    # After one roller spacing, roller i takes the place of roller i+1.
    assert np.allclose(shifted.screw_roller_n[:, 0], result.screw_roller_n[:, 1], rtol=1e-8)
    no_radial = solve_load_distribution(D000, 20_000.0, carrier_angle_rad=theta)
    assert np.ptp(no_radial.screw_roller_n[:, 0, 0]) == 0.0


def test_larger_clearance_unloads_its_roller() -> None:
    clearance = np.zeros((M004.n_rollers, M004.n_threads))
    clearance[3] += 5e-6
    result = solve_load_distribution(M004, 30_000.0, clearance_screw_roller_m=clearance)
    loads = result.roller_axial_load_n
    assert np.argmin(loads) == 3
    assert loads[3] < 0.9 * np.delete(loads, 3).mean()
    assert loads.sum() == pytest.approx(30_000.0, rel=1e-9)


def test_long_roller_has_no_shooting_instability() -> None:
    """The README's pitfall: shooting fails at >= 40 threads; the whole-system solve does not."""
    long_roller = dataclasses.replace(M004, n_threads=80)
    result = solve_load_distribution(long_roller, 50_000.0)
    loads = result.screw_roller_n
    assert np.all(np.isfinite(loads)) and np.all(loads >= 0.0)
    assert np.all(np.diff(loads, axis=-1) <= 0.0)
    assert loads.sum() * long_roller.axial_projection == pytest.approx(50_000.0, rel=1e-9)


def test_batch_equals_individual_solves() -> None:
    loads = np.array([5_000.0, 25_000.0])
    batch = solve_load_distribution(D000, loads, radial_load_n=3_000.0)
    for k, axial in enumerate(loads):
        single = solve_load_distribution(D000, axial, radial_load_n=3_000.0)
        assert np.allclose(batch.screw_roller_n[k], single.screw_roller_n, rtol=1e-9)


def test_zero_load_gives_zero_forces_and_radial_without_axial_is_a_domain_error() -> None:
    result = solve_load_distribution(D000, [0.0, 10_000.0], radial_load_n=[0.0, 1_000.0])
    assert not result.screw_roller_n[0].any()
    assert result.screw_roller_n[1].sum() > 0.0
    with pytest.raises(DomainError, match="radial load without axial load"):
        solve_load_distribution(M004, 0.0, radial_load_n=100.0)


def test_denormal_and_negligible_loads_are_zero_without_overflow() -> None:
    loads = [2.2e-313, 1e-10, 0.9 * NEGLIGIBLE_LOAD_N, 2 * NEGLIGIBLE_LOAD_N]
    with np.errstate(over="raise", divide="raise", invalid="raise"):
        result = solve_load_distribution(D000, loads)
    assert not result.screw_roller_n[:3].any()
    assert result.screw_roller_n[3].sum() * D000.axial_projection == pytest.approx(loads[3])


def test_radial_load_beyond_capacity_is_a_domain_error() -> None:
    with pytest.raises(DomainError, match="opposite flank"):
        solve_load_distribution(D000, 5_000.0, radial_load_n=20_000.0)


def test_radial_capacity_depends_on_where_the_rollers_are() -> None:
    """Between two rollers the balanceable radial load is the N-gon of the roller directions:
    12 degrees off a roller (N = 10) it is cos(18 deg) / cos(6 deg) of the value with a roller
    facing the load. Just below it the solve converges and balances the screw; just above it
    is a DomainError (it was a ConvergenceError with the facing-roller bound)."""
    theta = math.radians(12.0)
    facing = float(radial_capacity_ratio(D000))
    at_theta = float(radial_capacity_ratio(D000, theta))
    assert at_theta / facing == pytest.approx(
        math.cos(math.radians(18)) / math.cos(math.radians(6))
    )
    axial = 10_000.0
    result = solve_load_distribution(
        D000, axial, radial_load_n=0.9999 * at_theta * axial, carrier_angle_rad=theta
    )
    assert result.residual <= 1e-11
    assert result.roller_axial_load_n.sum() == pytest.approx(axial, rel=1e-9)
    with pytest.raises(DomainError, match="carrier angle"):
        solve_load_distribution(
            D000, axial, radial_load_n=1.0001 * at_theta * axial, carrier_angle_rad=theta
        )


def test_far_rollers_float_at_high_radial_ratio_and_equilibrium_holds() -> None:
    """Downhole cycle extreme (10 kN axial, 8 kN radial): far rollers unload completely."""
    result = solve_load_distribution(D000, 10_000.0, radial_load_n=8_000.0)
    per_roller = result.roller_axial_load_n
    assert np.any(per_roller == 0.0)
    assert per_roller.sum() == pytest.approx(10_000.0, rel=1e-9)


def test_unconverged_solve_raises_with_residual(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(load_distribution, "MAX_ITERATIONS", 1)
    with pytest.raises(ConvergenceError, match="did not converge in 1 iterations: scaled resid"):
        solve_load_distribution(D000, 20_000.0, radial_load_n=4_000.0)


@pytest.mark.parametrize("bad", [math.nan, -1.0, math.inf])
def test_invalid_load_is_refused_naming_it(bad: float) -> None:
    with pytest.raises(ParameterError, match="axial_load_n"):
        solve_load_distribution(M004, bad)


@settings(max_examples=40, deadline=None)
@given(
    name=st.sampled_from(PRESET_NAMES),
    fraction=st.floats(min_value=0.0, max_value=3.0),
    radial_ratio=st.floats(min_value=0.0, max_value=0.95),
    theta=st.floats(min_value=0.0, max_value=2 * math.pi),
    case=st.sampled_from(list(LoadingCase)),
)
def test_property_finite_nonnegative_balanced_or_domain_error(
    name: str, fraction: float, radial_ratio: float, theta: float, case: LoadingCase
) -> None:
    preset = load_preset(name)
    axial = fraction * preset.largest_axial_load_n
    try:
        result = solve_load_distribution(
            preset.geometry,
            axial,
            radial_load_n=radial_ratio * axial,
            carrier_angle_rad=theta,
            case=case,
        )
    except DomainError:
        assert axial == 0.0 and radial_ratio > 0.0  # below capacity only F_a = 0 may fail
        return
    q = result.screw_roller_n
    assert np.all(np.isfinite(q)) and np.all(q >= 0.0)
    carried = axial if axial > NEGLIGIBLE_LOAD_N else 0.0
    assert q.sum() * preset.geometry.axial_projection == pytest.approx(carried, rel=1e-9)


@settings(max_examples=20, deadline=None)
@given(name=st.sampled_from(PRESET_NAMES), low=st.floats(0.01, 1.0), step=st.floats(0.01, 2.0))
def test_property_every_contact_load_grows_with_axial_load(
    name: str, low: float, step: float
) -> None:
    preset = load_preset(name)
    loads = preset.largest_axial_load_n * np.array([low, low + step])
    result = solve_load_distribution(preset.geometry, loads)
    assert np.all(result.screw_roller_n[1] > result.screw_roller_n[0])
