"""Tests of the unloaded meshing: axial clearances, contact points, slip speed (papers 001, 004)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.typing import NDArray
from scipy.optimize import minimize

from prsm_health.physics.errors import DomainError, ParameterError
from prsm_health.physics.geometry import Geometry, Misalignment
from prsm_health.physics.meshing import (
    Meshing,
    carrier_speed_rad_s,
    meshing,
    roller_flank_height_m,
    screw_flank_height_m,
    slip_speed_m_s,
    smallest_misaligned_clearance,
)
from prsm_health.physics.presets import PRESET_NAMES, load_preset

FloatArray = NDArray[np.float64]


@pytest.fixture(scope="module")
def geometry() -> Geometry:
    return load_preset("meng2022-misalignment").geometry


def _rot_x(angle: float) -> FloatArray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_y(angle: float) -> FloatArray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rot_z(angle: float) -> FloatArray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


# --- aligned clearances and contact points ---------------------------------------------------


def test_aligned_clearance_matches_paper_004(geometry: Geometry) -> None:
    """004 section 3.1 / Fig. 8: every aligned screw-roller clearance is 0.023 mm."""
    state = meshing(geometry, Misalignment())
    clearance = state.axial_clearance_screw_roller_m
    assert clearance.shape == (geometry.n_rollers, geometry.n_threads)
    np.testing.assert_allclose(clearance, 0.023e-3, rtol=0.03)
    assert np.ptp(clearance) == 0.0


def test_aligned_clearance_matches_second_order_expansion(geometry: Geometry) -> None:
    """Independent estimate: expand the gap along the line x = r_s to second order in y.

    Gap = (p/2 - c_s - c_r) - (tan lambda_s + tan lambda_r) y + tan(beta) (1/r_s + 1/r_r) y^2 / 2
    (same-hand helices add up); its minimum and minimiser must agree with the search.
    """
    g = geometry
    linear = g.lead_m / (2 * math.pi * g.screw_radius_m) + g.pitch_m / (
        2 * math.pi * g.roller_radius_m
    )
    quadratic = math.tan(g.flank_angle_rad) * (1 / g.screw_radius_m + 1 / g.roller_radius_m) / 2
    nominal = g.pitch_m / 2 - g.thread_half_thickness_screw_m - g.thread_half_thickness_roller_m
    estimate = nominal - linear**2 / (4 * quadratic)
    offset_estimate = linear / (2 * quadratic)
    state = meshing(g, Misalignment())
    assert state.axial_clearance_screw_roller_m[0, 0] == pytest.approx(estimate, rel=0.05)
    offset = state.contact_radius_screw_m * math.sin(state.contact_angle_screw_rad)
    assert offset == pytest.approx(offset_estimate, rel=0.05)
    # the same contact point seen from the roller axis
    roller_offset = state.contact_radius_roller_m * math.sin(state.contact_angle_roller_rad)
    assert roller_offset == pytest.approx(offset, rel=1e-9)
    # "the contact point positions are always away from the center line" (004 section 3.1)
    assert state.contact_angle_screw_rad > 0.0
    assert state.contact_angle_roller_rad > state.contact_angle_screw_rad


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_contact_search_finds_global_minimum(name: str) -> None:
    """A fine brute-force grid over the flank band never goes below the refined minimum."""
    g = load_preset(name).geometry
    state = meshing(g, Misalignment())
    centre = g.carrier_radius_m
    xs = np.linspace(centre - g.roller_crest_radius_m, g.screw_crest_radius_m, 700)
    ys = np.linspace(-g.roller_crest_radius_m, g.roller_crest_radius_m, 1400)
    x, y = np.meshgrid(xs, ys)
    rho_s, rho_r = np.hypot(x, y), np.hypot(x - centre, y)
    inside = (
        (rho_s >= g.screw_root_radius_m)
        & (rho_s <= g.screw_crest_radius_m)
        & (rho_r >= g.roller_root_radius_m)
        & (rho_r <= g.roller_crest_radius_m)
    )
    gap = roller_flank_height_m(g, x, y) - screw_flank_height_m(g, x, y)
    brute = float(np.min(gap[inside]))
    found = float(state.axial_clearance_screw_roller_m[0, 0])
    assert found > 0.0
    assert found <= brute + 1e-12
    assert found == pytest.approx(brute, abs=2e-9)


def test_roller_nut_clearance_is_nominal_gap_at_pitch_point(geometry: Geometry) -> None:
    """Nut and roller have equal helix angles, so the gap is least on the line of centres."""
    g = geometry
    state = meshing(g, Misalignment.from_arcmin(1.0, 1.0))
    expected = g.pitch_m / 2 - g.thread_half_thickness_roller_m - g.thread_half_thickness_nut_m
    np.testing.assert_allclose(state.axial_clearance_roller_nut_m, expected, atol=1e-11)


def test_overlapping_aligned_threads_are_refused(geometry: Geometry) -> None:
    thick = dataclasses.replace(geometry, thread_half_thickness_screw_m=0.53e-3)
    with pytest.raises(ParameterError) as info:
        meshing(thick, Misalignment())
    assert info.value.field == "geometry.thread_half_thickness_screw_m"


# --- misalignment ----------------------------------------------------------------------------


def test_one_arcmin_tilt_matches_paper_004(geometry: Geometry) -> None:
    """004 section 3.1, Fig. 8a: roller 4# changes 0.57 um per thread, 10.9 um over 20 threads."""
    aligned = meshing(geometry, Misalignment()).axial_clearance_screw_roller_m
    tilted = meshing(geometry, Misalignment.from_arcmin(1.0, 0.0)).axial_clearance_screw_roller_m
    steps = np.diff(tilted, axis=1)
    # the step is the same at every thread of a roller (tilt is linear along the axis)
    np.testing.assert_allclose(steps, steps[:, :1] * np.ones_like(steps), atol=1e-12)
    spread = np.ptp(tilted, axis=1)
    worst = int(np.argmax(spread))
    assert worst in (3, 8)  # roller 4# or the one opposite
    assert abs(steps[worst, 0]) == pytest.approx(0.57e-6, rel=0.05)
    assert spread[worst] == pytest.approx(10.9e-6, rel=0.05)
    # roller i and the one opposite change in opposite directions
    change = tilted - aligned
    half = geometry.n_rollers // 2
    np.testing.assert_allclose(change[:half], -change[half:], atol=1e-12)
    assert np.abs(change).max() > 5e-6


def test_tilt_about_y_is_tilt_about_x_turned_a_quarter(geometry: Geometry) -> None:
    tilt_x = meshing(geometry, Misalignment.from_arcmin(1.0, 0.0))
    tilt_y = meshing(geometry, Misalignment.from_arcmin(0.0, 1.0), carrier_angle_rad=math.pi / 2)
    np.testing.assert_allclose(
        tilt_y.axial_clearance_screw_roller_m, tilt_x.axial_clearance_screw_roller_m, atol=1e-12
    )


def _exact_clearance(g: Geometry, misalignment: Misalignment, roller: int, thread: int) -> float:
    """Clearance of one thread by direct minimisation over the rigidly moved screw flank.

    The screw flank of roller i, thread j (aligned: the roller-frame surface raised by j p,
    turned to tau_i) is moved by the rotation R_y R_x about the origin plus the offset; its
    height at a point is found by fixed-point iteration on the inverse motion.
    """
    turn = _rot_z(2 * math.pi * roller / g.n_rollers)
    motion = _rot_y(misalignment.tilt_y_rad) @ _rot_x(misalignment.tilt_x_rad)
    offset = np.array([misalignment.offset_x_m, misalignment.offset_y_m, 0.0])
    shift = thread * g.pitch_m

    def gap(v: FloatArray) -> float:
        x, y = v * 1e-3
        point = turn @ np.array([x, y, 0.0])
        z = float(screw_flank_height_m(g, x, y)) + shift
        for _ in range(30):
            point[2] = z
            source = turn.T @ (motion.T @ (point - offset))
            target = float(screw_flank_height_m(g, source[0], source[1])) + shift
            z -= source[2] - target
        roller_z = float(roller_flank_height_m(g, x, y)) + shift
        return (roller_z - z) * 1e3

    aligned = meshing(g, Misalignment())
    start = np.array(
        [
            aligned.contact_radius_screw_m * math.cos(aligned.contact_angle_screw_rad),
            aligned.contact_radius_screw_m * math.sin(aligned.contact_angle_screw_rad),
        ]
    )
    result = minimize(
        gap, start * 1e3, method="Nelder-Mead", options={"xatol": 1e-7, "fatol": 1e-12}
    )
    return float(result.fun) * 1e-3


@pytest.mark.parametrize(
    ("misalignment", "roller", "thread"),
    [
        (Misalignment.from_arcmin(1.0, 0.0), 3, 19),
        (
            Misalignment(
                tilt_x_rad=math.radians(1.5 / 60),
                tilt_y_rad=math.radians(-1 / 60),
                offset_x_m=10e-6,
                offset_y_m=-10e-6,
            ),
            6,
            12,
        ),
    ],
)
def test_first_order_clearance_matches_exact_minimisation(
    geometry: Geometry, misalignment: Misalignment, roller: int, thread: int
) -> None:
    fast = meshing(geometry, misalignment).axial_clearance_screw_roller_m[roller, thread]
    exact = _exact_clearance(geometry, misalignment, roller, thread)
    aligned = meshing(geometry, Misalignment()).axial_clearance_screw_roller_m[0, 0]
    assert abs(exact - aligned) > 2e-6  # the case really moves the clearance
    assert fast == pytest.approx(exact, abs=0.02e-6)


def test_overlapping_flanks_raise_domain_error_naming_the_thread(geometry: Geometry) -> None:
    with pytest.raises(DomainError, match=r"roller \d+, thread \d+"):
        meshing(geometry, Misalignment(offset_x_m=0.1e-3))


@pytest.mark.parametrize("name", PRESET_NAMES)
@pytest.mark.parametrize(
    "misalignment",
    [
        Misalignment.from_arcmin(2.0, 0.0),
        Misalignment.from_arcmin(1.0, -1.5),
        Misalignment(tilt_y_rad=1e-4, offset_x_m=3e-6, offset_y_m=-2e-6),
    ],
)
def test_smallest_misaligned_clearance_is_the_minimum_over_every_carrier_angle(
    name: str, misalignment: Misalignment
) -> None:
    """The closed form against meshing itself on 2,000 carrier angles per roller spacing: no
    sample is below it, the densest is within a micrometre's millionth of it, and meshing at
    its angle reaches it on its thread."""
    g = load_preset(name).geometry
    clearance, thread, angle = smallest_misaligned_clearance(g, misalignment)
    spacing = 2.0 * math.pi / g.n_rollers
    sampled = np.array(
        [
            meshing(g, misalignment, carrier_angle_rad=float(a)).axial_clearance_screw_roller_m
            for a in np.linspace(0.0, spacing, 2000, endpoint=False)
        ]
    )
    aligned = meshing(g, Misalignment()).axial_clearance_screw_roller_m[0, 0]
    assert aligned - clearance > 1e-6  # the case really closes the clearance
    assert sampled.min() >= clearance - 1e-18
    assert sampled.min() == pytest.approx(clearance, abs=1e-12)
    at_angle = meshing(g, misalignment, carrier_angle_rad=angle).axial_clearance_screw_roller_m
    assert at_angle[0, thread] == pytest.approx(clearance, abs=1e-18)
    assert at_angle.min() == pytest.approx(clearance, abs=1e-18)


def test_meshing_is_cached_and_read_only(geometry: Geometry) -> None:
    misalignment = Misalignment.from_arcmin(1.0, 0.0)
    state = meshing(geometry, misalignment)
    assert meshing(geometry, Misalignment.from_arcmin(1.0, 0.0)) is state
    with pytest.raises(ValueError, match="read-only"):
        state.axial_clearance_screw_roller_m[0, 0] = 0.0


def test_non_finite_carrier_angle_is_refused(geometry: Geometry) -> None:
    with pytest.raises(ParameterError) as info:
        meshing(geometry, Misalignment(), carrier_angle_rad=math.nan)
    assert info.value.field == "carrier_angle_rad"


# --- kinematics and slip ----------------------------------------------------------------------


def _velocities(
    g: Geometry, state: Meshing, screw_speed: float, roller_spin_abs: float
) -> FloatArray:
    """Screw minus roller material velocity at the contact point, built from vectors."""
    carrier = float(carrier_speed_rad_s(g, screw_speed))
    axis = np.array([0.0, 0.0, 1.0])
    point = state.contact_radius_screw_m * np.array(
        [math.cos(state.contact_angle_screw_rad), math.sin(state.contact_angle_screw_rad), 0.0]
    )
    centre = np.array([g.carrier_radius_m, 0.0, 0.0])
    screw = screw_speed * np.cross(axis, point)
    # rollers ride with the nut axially; relative to the screw they advance one lead per turn
    roller = (
        carrier * np.cross(axis, centre)
        + roller_spin_abs * np.cross(axis, point - centre)
        - g.lead_m * screw_speed / (2 * math.pi) * axis
    )
    return np.asarray(screw - roller, dtype=float)


def test_carrier_speed_gives_rolling_at_both_pitch_points(geometry: Geometry) -> None:
    g = geometry
    screw_speed = 31.4
    carrier = float(carrier_speed_rad_s(g, screw_speed))
    spin = -carrier * g.carrier_radius_m / g.roller_radius_m  # rolls on the fixed nut
    at_screw_pitch_point = carrier * g.carrier_radius_m - spin * g.roller_radius_m
    assert at_screw_pitch_point == pytest.approx(screw_speed * g.screw_radius_m, rel=1e-12)


@pytest.mark.parametrize("name", PRESET_NAMES)
@pytest.mark.parametrize("screw_speed", [31.4, -12.0])
def test_slip_speed_equals_vector_relative_velocity(name: str, screw_speed: float) -> None:
    g = load_preset(name).geometry
    state = meshing(g, Misalignment())
    carrier = float(carrier_speed_rad_s(g, screw_speed))
    rolling_spin = -carrier * g.carrier_radius_m / g.roller_radius_m
    expected = np.linalg.norm(_velocities(g, state, screw_speed, rolling_spin))
    assert float(slip_speed_m_s(g, state, screw_speed)) == pytest.approx(expected, rel=1e-12)
    jammed = np.linalg.norm(_velocities(g, state, screw_speed, carrier))  # seized on carrier
    assert float(slip_speed_m_s(g, state, screw_speed, jammed=True)) == pytest.approx(
        jammed, rel=1e-12
    )
    assert jammed > 2 * expected


def test_tangential_slip_cancels_at_the_pitch_point(geometry: Geometry) -> None:
    """With the contact on the line of centres only the axial sliding (one lead/turn) is left."""
    g = geometry
    pitch_point = Meshing(
        axial_clearance_screw_roller_m=np.zeros((1, 1)),
        axial_clearance_roller_nut_m=np.zeros((1, 1)),
        contact_angle_screw_rad=0.0,
        contact_angle_roller_rad=0.0,
        contact_radius_screw_m=g.screw_radius_m,
        contact_radius_roller_m=g.roller_radius_m,
    )
    speed = np.array([0.0, 10.0, -25.0])
    np.testing.assert_allclose(
        slip_speed_m_s(g, pitch_point, speed), np.abs(speed) * g.lead_m / (2 * math.pi)
    )
    real = slip_speed_m_s(g, meshing(g, Misalignment()), speed)
    assert np.all(real[1:] > np.abs(speed[1:]) * g.lead_m / (2 * math.pi))


@settings(max_examples=40, deadline=None)
@given(
    speeds=st.lists(
        st.floats(min_value=-400.0, max_value=400.0, allow_nan=False), min_size=1, max_size=6
    ),
    factor=st.floats(min_value=-20.0, max_value=20.0, allow_nan=False),
    jammed=st.booleans(),
)
def test_slip_speed_is_proportional_to_screw_speed(
    speeds: list[float], factor: float, jammed: bool
) -> None:
    g = load_preset("meng2022-misalignment").geometry
    state = meshing(g, Misalignment())
    base = slip_speed_m_s(g, state, np.array(speeds), jammed=jammed)
    scaled = slip_speed_m_s(g, state, factor * np.array(speeds), jammed=jammed)
    assert base.shape == (len(speeds),)
    assert np.all(base >= 0.0)
    np.testing.assert_allclose(scaled, abs(factor) * base, rtol=1e-9, atol=1e-15)
    assert float(slip_speed_m_s(g, state, 0.0, jammed=jammed)) == 0.0


def test_slip_speed_is_vectorised_over_leading_dims(geometry: Geometry) -> None:
    state = meshing(geometry, Misalignment())
    speeds = np.linspace(-30.0, 30.0, 12).reshape(3, 4)
    slip = slip_speed_m_s(geometry, state, speeds)
    assert slip.shape == (3, 4)
    np.testing.assert_allclose(slip[0, 1], slip_speed_m_s(geometry, state, speeds[0, 1]))


def test_non_finite_speed_is_refused(geometry: Geometry) -> None:
    state = meshing(geometry, Misalignment())
    with pytest.raises(ParameterError) as info:
        slip_speed_m_s(geometry, state, [1.0, math.inf])
    assert info.value.field == "screw_speed_rad_s"
