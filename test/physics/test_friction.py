"""Friction torque, jammed rollers and efficiency (paper 002) against independent calculations."""

from __future__ import annotations

import math
import warnings
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from scipy.integrate import dblquad
from scipy.special import ellipe

from prsm_health.physics.errors import DomainError, ParameterError
from prsm_health.physics.friction import (
    efficiency,
    friction_torque,
    jammed_to_rolling_ratio,
    rolling_speed_m_s,
    spin_integral,
)
from prsm_health.physics.geometry import Geometry
from prsm_health.physics.hertz import thread_contacts
from prsm_health.physics.presets import load_preset

PRESET = load_preset("li2020-jamming")
GEOMETRY = PRESET.geometry
PARAMS = PRESET.friction
N_ROLLERS, N_THREADS = GEOMETRY.n_rollers, GEOMETRY.n_threads
RPM = math.pi / 30.0


def profile(geometry: Geometry, axial_load_n: float, decay: float = 0.05) -> np.ndarray:
    """Equal rollers, loads falling from the loaded end, sum(Q) * projection = axial load."""
    shape = np.exp(-decay * np.arange(geometry.n_threads))
    per_roller = np.tile(shape, (geometry.n_rollers, 1))
    return per_roller * axial_load_n / (per_roller.sum() * geometry.axial_projection)


def arm(geometry: Geometry) -> float:
    """r_s r_n / (r_s + r_n) from the planetary kinematics (nut fixed, rolling at pitch)."""
    r_s, r_r = geometry.screw_radius_m, geometry.roller_radius_m
    carrier_per_screw = r_s / (2.0 * (r_s + r_r))  # roller centre at half the screw speed
    return (1.0 - carrier_per_screw) * r_s  # screw surface speed seen from the carrier


# --- closed forms and kinematics ----------------------------------------------------------
@pytest.mark.parametrize("kappa", [1.0, 1.7, 4.0])
def test_spin_integral_matches_direct_quadrature(kappa: float) -> None:
    a, b, load = 2.0e-4, 2.0e-4 / kappa, 130.0

    def integrand(y: float, x: float) -> float:
        pressure = (
            3 * load / (2 * math.pi * a * b) * math.sqrt(max(1 - (x / a) ** 2 - (y / b) ** 2, 0))
        )
        return pressure * math.hypot(x, y)

    direct, _ = dblquad(
        integrand,
        -a,
        a,
        lambda x: -b * math.sqrt(1 - (x / a) ** 2),
        lambda x: b * math.sqrt(1 - (x / a) ** 2),
        epsabs=0.0,
        epsrel=1e-7,
    )
    assert load * a * spin_integral(kappa) == pytest.approx(direct, rel=1e-6)


def test_spin_integral_circle_and_preset_contacts() -> None:
    assert spin_integral(1.0) == pytest.approx(3 * math.pi / 16, rel=1e-14)
    for pair in (thread_contacts(GEOMETRY).screw_roller, thread_contacts(GEOMETRY).roller_nut):
        assert spin_integral(pair.kappa) == pytest.approx(3 / 8 * pair.elliptic_e, rel=1e-12)
    with pytest.raises(ParameterError, match="kappa"):
        spin_integral(0.5)


def test_rolling_speed_is_the_planetary_rolling_speed() -> None:
    for name in ("li2020-jamming", "meng2022-misalignment", "dong2022-downhole"):
        geometry = load_preset(name).geometry
        omega = np.array([-50.0, 0.0, 31.4])
        np.testing.assert_allclose(
            rolling_speed_m_s(geometry, omega), np.abs(omega) * arm(geometry), rtol=1e-12
        )


def test_single_contacts_match_hand_calculation() -> None:
    """One loaded contact per interface, every term recomputed from the Hertz semi-axes."""
    q, omega = 180.0, 300 * RPM
    contacts = thread_contacts(GEOMETRY)
    beta, r_s, r_r = GEOMETRY.flank_angle_rad, GEOMETRY.screw_radius_m, GEOMETRY.roller_radius_m
    ball = GEOMETRY.effective_ball_radius_m
    v = omega * arm(GEOMETRY)
    f_s, gamma = PARAMS.sliding_friction_coefficient, PARAMS.hysteresis_loss_coefficient
    # Rolling-direction curvature sums written out from the flank geometry (hertz module doc).
    cases = [
        (
            contacts.screw_roller,
            1 / ball + math.cos(beta) / (r_s + r_r - ball * math.cos(beta)),
            r_s,
            +1,
        ),
        (
            contacts.roller_nut,
            1 / ball - math.cos(beta) / (r_s + r_r + ball * math.cos(beta)),
            r_s + 2 * r_r,
            -1,
        ),
    ]
    for index, (pair, rho_x, r_c, sign) in enumerate(cases):
        loads = [np.zeros((N_ROLLERS, N_THREADS)), np.zeros((N_ROLLERS, N_THREADS))]
        loads[index][3, 7] = q
        torque = friction_torque(GEOMETRY, PARAMS, loads[0], loads[1], omega)
        a, b = (float(x) for x in pair.semi_axes_m(q))
        rolling_axis, transverse_axis = (b, a) if rho_x > 1 / ball else (a, b)
        assert (rolling_axis == b) == (index == 0)  # the nut ellipse is long circumferentially
        hysteresis = 3 / 16 * gamma * rolling_axis * q * v * rho_x / omega
        spin_speed = v * math.sin(beta) * (1 / r_r + sign / r_c)
        m = 1 - (b / a) ** 2
        spin = 3 / 8 * float(ellipe(m)) * f_s * q * a * spin_speed / omega
        differential = 0.02 * f_s * q * (transverse_axis / ball) ** 2 * v / omega
        e_prime = 2 / pair.compliance_per_pa
        r_x, r_y = 1 / rho_x, ball
        viscous_force = (
            2.86
            * e_prime
            * r_x**2
            * (r_y / r_x) ** 0.348
            * (e_prime * PARAMS.pressure_viscosity_coefficient_per_pa) ** 0.022
            * (PARAMS.lubricant_viscosity_pa_s * v / (e_prime * r_x)) ** 0.66
            * (q / (e_prime * r_x**2)) ** 0.47
        )
        expected = {
            "hysteresis_nm": hysteresis,
            "spin_nm": spin,
            "differential_nm": differential,
            "viscous_nm": viscous_force * v / omega,
        }
        for field, value in expected.items():
            per_roller = getattr(torque, field)
            assert per_roller[3] == pytest.approx(value, rel=1e-10), field
            assert np.count_nonzero(per_roller) == 1
        assert not torque.jammed_sliding_nm.any()


# --- jammed rollers and efficiency ---------------------------------------------------------
@pytest.mark.parametrize(("axial_load_n", "rpm"), [(5800.0, 100.0), (15000.0, 1000.0)])
def test_equal_rollers_reduce_to_eq17(axial_load_n: float, rpm: float) -> None:
    q = profile(GEOMETRY, axial_load_n)
    healthy = friction_torque(GEOMETRY, PARAMS, q, q, rpm * RPM)
    all_jammed = friction_torque(GEOMETRY, PARAMS, q, q, rpm * RPM, jammed=N_ROLLERS)
    r = all_jammed.per_roller_nm[0] / healthy.per_roller_nm[0]
    assert r > 1
    np.testing.assert_allclose(
        jammed_to_rolling_ratio(GEOMETRY, PARAMS, q, q, rpm * RPM), r, rtol=1e-14
    )
    for x in range(N_ROLLERS + 1):
        ratio = (
            friction_torque(GEOMETRY, PARAMS, q, q, rpm * RPM, jammed=x).total_nm / healthy.total_nm
        )
        assert ratio == pytest.approx(1 + x * (r - 1) / N_ROLLERS, rel=1e-12)


def test_all_jammed_is_coulomb_sliding() -> None:
    """f_s sum(Q) per interface with sum(Q) = F / projection: eta independent of the load."""
    f_s = PARAMS.sliding_friction_coefficient
    lead_torque_per_n = GEOMETRY.lead_m / (2 * math.pi)
    expected_eta = lead_torque_per_n / (
        lead_torque_per_n + 2 * f_s * arm(GEOMETRY) / GEOMETRY.axial_projection
    )
    for load in (5800.0, 15000.0):
        q = profile(GEOMETRY, load, decay=0.1)
        torque = friction_torque(GEOMETRY, PARAMS, q, q, 0.0, jammed=N_ROLLERS).total_nm
        assert torque == pytest.approx(
            2 * f_s * arm(GEOMETRY) * load / GEOMETRY.axial_projection, rel=1e-12
        )
        assert efficiency(GEOMETRY, load, torque) == pytest.approx(expected_eta, rel=1e-12)


def test_efficiency_falls_monotonically_with_jammed_rollers() -> None:
    load = 15000.0
    q = profile(GEOMETRY, load)
    torques = np.array(
        [
            friction_torque(GEOMETRY, PARAMS, q, q, 300 * RPM, jammed=x).total_nm
            for x in range(N_ROLLERS + 1)
        ]
    )
    eta = efficiency(GEOMETRY, load, torques)
    assert np.all(np.diff(eta) < 0)
    assert 0 < eta[-1] < eta[0] < 1
    hand = load * GEOMETRY.lead_m / (2 * math.pi)
    assert eta[0] == pytest.approx(hand / (hand + torques[0]), rel=1e-14)


def test_efficiency_at_zero_load_is_zero_and_quiet() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        eta = efficiency(GEOMETRY, np.array([0.0, 0.0, 100.0]), np.array([0.0, 0.2, 0.0]))
    np.testing.assert_array_equal(eta, [0.0, 0.0, 1.0])
    with pytest.raises(ParameterError, match="axial_load_n"):
        efficiency(GEOMETRY, -1.0, 0.1)
    with pytest.raises(ParameterError, match="friction_torque_nm"):
        efficiency(GEOMETRY, 1.0, math.nan)


def test_unequal_rollers_mask_and_count() -> None:
    """Per-roller jamming: the most loaded roller costs most; count x = first x of the mask."""
    weights = np.linspace(0.6, 1.4, N_ROLLERS)[:, np.newaxis]
    q = profile(GEOMETRY, 10000.0) * weights
    omega = 200 * RPM
    heavy = np.zeros(N_ROLLERS, dtype=bool)
    heavy[-1] = True
    light = heavy[::-1].copy()
    m_heavy = friction_torque(GEOMETRY, PARAMS, q, q, omega, jammed=heavy).total_nm
    m_light = friction_torque(GEOMETRY, PARAMS, q, q, omega, jammed=light).total_nm
    m_none = friction_torque(GEOMETRY, PARAMS, q, q, omega).total_nm
    assert m_heavy > m_light > m_none
    by_count = friction_torque(GEOMETRY, PARAMS, q, q, omega, jammed=3)
    by_mask = friction_torque(GEOMETRY, PARAMS, q, q, omega, jammed=np.arange(N_ROLLERS) < 3)
    np.testing.assert_array_equal(by_count.per_roller_nm, by_mask.per_roller_nm)
    assert not by_count.viscous_nm[:3].any() and not by_count.jammed_sliding_nm[3:].any()


# --- load and speed dependence ------------------------------------------------------------
def test_viscous_term_grows_with_speed_and_vanishes_at_rest() -> None:
    q = profile(GEOMETRY, 5800.0)
    omegas = np.array([0.0, 10.0, 100.0, -100.0])
    torque = friction_torque(GEOMETRY, PARAMS, q, q, omegas)
    viscous = torque.viscous_nm.sum(axis=-1)
    assert viscous[0] == 0.0 and 0 < viscous[1] < viscous[2]
    assert viscous[2] / viscous[1] == pytest.approx(10**0.66, rel=1e-12)  # U^0.66 of eq. 5
    assert viscous[3] == viscous[2]  # magnitudes: the sign of the speed is the caller's
    np.testing.assert_array_equal(torque.spin_nm[0], torque.spin_nm[2])  # load terms speed-free
    assert torque.total_nm[0] > 0  # breakaway estimate at standstill


def test_torque_increases_with_load() -> None:
    totals = [
        friction_torque(
            GEOMETRY, PARAMS, profile(GEOMETRY, f), profile(GEOMETRY, f), 300 * RPM
        ).total_nm
        for f in (1000.0, 5800.0, 15000.0)
    ]
    assert totals[0] < totals[1] < totals[2]


def test_batches_match_single_evaluations_and_speed_broadcasts() -> None:
    rng = np.random.default_rng(7)
    batch_sr = rng.uniform(0, 200, (4, 3, N_ROLLERS, N_THREADS))
    batch_rn = rng.uniform(0, 200, batch_sr.shape)
    speeds = rng.uniform(-100, 100, (4, 1))
    torque = friction_torque(GEOMETRY, PARAMS, batch_sr, batch_rn, speeds, jammed=2)
    assert torque.per_roller_nm.shape == (4, 3, N_ROLLERS) and torque.total_nm.shape == (4, 3)
    for i in range(4):
        for j in range(3):
            single = friction_torque(
                GEOMETRY, PARAMS, batch_sr[i, j], batch_rn[i, j], speeds[i, 0], jammed=2
            )
            np.testing.assert_allclose(torque.per_roller_nm[i, j], single.per_roller_nm, rtol=1e-13)
    fanned = friction_torque(
        GEOMETRY, PARAMS, batch_sr[0, 0], batch_rn[0, 0], np.array([0.0, 5.0, 50.0])
    )
    assert fanned.per_roller_nm.shape == (3, N_ROLLERS)
    np.testing.assert_array_equal(fanned.hysteresis_nm[0], fanned.hysteresis_nm[2])


load_arrays = hnp.arrays(
    np.float64,
    (2, N_ROLLERS, N_THREADS),
    elements=st.one_of(st.just(0.0), st.floats(min_value=1e-3, max_value=5.0e4)),
)


@settings(max_examples=60, deadline=None)
@given(load_arrays, st.floats(min_value=-500.0, max_value=500.0), st.integers(0, N_ROLLERS))
def test_torque_is_finite_and_non_negative(loads: np.ndarray, omega: float, x: int) -> None:
    torque = friction_torque(GEOMETRY, PARAMS, loads[0], loads[1], omega, jammed=x)
    for field in ("hysteresis_nm", "spin_nm", "differential_nm", "viscous_nm", "jammed_sliding_nm"):
        value = getattr(torque, field)
        assert value.shape == (N_ROLLERS,)
        assert np.all(np.isfinite(value)) and np.all(value >= 0)
    eta = efficiency(GEOMETRY, loads[0].sum() * GEOMETRY.axial_projection, torque.total_nm)
    assert 0.0 <= eta <= 1.0


@settings(max_examples=40, deadline=None)
@given(
    load_arrays,
    st.floats(min_value=1.01, max_value=10.0),
    st.floats(min_value=0.0, max_value=500.0),
)
def test_scaling_loads_up_never_lowers_the_torque(
    loads: np.ndarray, scale: float, omega: float
) -> None:
    base = friction_torque(GEOMETRY, PARAMS, loads[0], loads[1], omega).per_roller_nm
    scaled = friction_torque(
        GEOMETRY, PARAMS, scale * loads[0], scale * loads[1], omega
    ).per_roller_nm
    loaded = loads.sum(axis=(0, 2)) > 0
    assert np.all(scaled[loaded] > base[loaded]) and np.all(scaled[~loaded] == 0)


# --- input validation ----------------------------------------------------------------------
def test_invalid_inputs_raise_typed_errors() -> None:
    q = profile(GEOMETRY, 5000.0)
    bad = q.copy()
    bad[2, 2] = math.nan
    with pytest.raises(ParameterError, match="roller_nut_n") as info:
        friction_torque(GEOMETRY, PARAMS, q, bad, 1.0)
    assert info.value.field == "roller_nut_n"
    with pytest.raises(ParameterError, match="screw_roller_n"):
        friction_torque(GEOMETRY, PARAMS, -q, q, 1.0)
    with pytest.raises(ParameterError, match="screw_roller_n"):
        friction_torque(GEOMETRY, PARAMS, np.full_like(q, math.inf), q, 1.0)
    with pytest.raises(ParameterError, match="screw_roller_n"):
        friction_torque(GEOMETRY, PARAMS, q[:, :-1], q, 1.0)
    with pytest.raises(ParameterError, match="roller_nut_n"):
        friction_torque(GEOMETRY, PARAMS, q, q[np.newaxis], 1.0)
    with pytest.raises(ParameterError, match="screw_speed_rad_s"):
        friction_torque(GEOMETRY, PARAMS, q, q, math.nan)
    with pytest.raises(ParameterError, match="screw_speed_rad_s"):
        friction_torque(GEOMETRY, PARAMS, np.stack([q, q]), np.stack([q, q]), np.ones(3))
    with pytest.raises(ParameterError, match="jammed"):
        friction_torque(GEOMETRY, PARAMS, q, q, 1.0, jammed=N_ROLLERS + 1)
    with pytest.raises(ParameterError, match="jammed"):
        friction_torque(GEOMETRY, PARAMS, q, q, 1.0, jammed=np.ones(N_ROLLERS))
    with pytest.raises(ParameterError, match="jammed"):
        friction_torque(GEOMETRY, PARAMS, q, q, 1.0, jammed=np.ones(N_ROLLERS - 1, dtype=bool))
    unloaded = q.copy()
    unloaded[4] = 0.0
    with pytest.raises(DomainError):
        jammed_to_rolling_ratio(GEOMETRY, PARAMS, unloaded, unloaded, 1.0)


def test_parameters_change_the_terms_they_own() -> None:
    q = profile(GEOMETRY, 5800.0)
    base = friction_torque(GEOMETRY, PARAMS, q, q, 100.0)
    thicker = replace(PARAMS, lubricant_viscosity_pa_s=2 * PARAMS.lubricant_viscosity_pa_s)
    doubled = friction_torque(GEOMETRY, thicker, q, q, 100.0)
    np.testing.assert_allclose(doubled.viscous_nm, base.viscous_nm * 2**0.66, rtol=1e-12)
    np.testing.assert_array_equal(doubled.spin_nm, base.spin_nm)
