"""Hertz contact against closed-form limits and the papers' definitions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from prsm_health.physics.geometry import Material
from prsm_health.physics.hertz import ellipticity, make_contact_pair, thread_contacts
from prsm_health.physics.presets import PRESET_NAMES, load_preset


def test_sphere_on_flat_matches_classical_hertz() -> None:
    steel = Material()
    radius, load = 5e-3, 120.0
    pair = make_contact_pair((1 / radius, 1 / radius), (0.0, 0.0), steel, steel)
    e_star = 1.0 / pair.compliance_per_pa
    a_classic = (3 * load * radius / (4 * e_star)) ** (1 / 3)
    a, b = pair.semi_axes_m(load)
    assert a == pytest.approx(a_classic, rel=1e-9, abs=0.0)
    assert b == pytest.approx(a_classic, rel=1e-9, abs=0.0)
    assert pair.approach_m(load) == pytest.approx(a_classic**2 / radius, rel=1e-9, abs=0.0)
    assert pair.max_pressure_pa(load) == pytest.approx(3 * load / (2 * math.pi * a_classic**2))


def test_cylinder_like_ellipse_is_elongated_along_the_flat_direction() -> None:
    steel = Material()
    pair = make_contact_pair((100.0, 10.0), (0.0, 0.0), steel, steel)
    a, b = pair.semi_axes_m(50.0)
    assert pair.kappa > 3.0 and a / b == pytest.approx(pair.kappa)


@given(st.floats(min_value=0.0, max_value=0.99))
def test_ellipticity_inverts_the_curvature_difference(difference: float) -> None:
    from prsm_health.physics.hertz import _curvature_difference

    kappa = ellipticity(difference)
    # The closed form F(kappa) carries ~1e-11 absolute rounding near kappa = 1, so the
    # inversion is checked in absolute terms, and against the series F = 3/4 (kappa - 1).
    assert _curvature_difference(kappa) == pytest.approx(difference, abs=1e-9)
    if difference < 1e-4:
        assert kappa - 1.0 == pytest.approx(difference / 0.75, abs=1e-8)


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_load_and_approach_are_inverse_and_smooth_through_zero(name: str) -> None:
    pair = thread_contacts(load_preset(name).geometry).screw_roller
    loads = np.array([0.0, 1.0, 100.0, 2000.0])
    assert np.allclose(pair.load_n(pair.approach_m(loads)), loads, rtol=1e-12)
    assert pair.load_n(-1e-6) == 0.0
    assert pair.max_pressure_pa(0.0) == 0.0


def test_nut_side_is_conformal_so_softer_than_screw_side() -> None:
    contacts = thread_contacts(load_preset("meng2022-misalignment").geometry)
    assert contacts.roller_nut.curvature_sum_per_m < contacts.screw_roller.curvature_sum_per_m
    assert contacts.roller_nut.max_pressure_pa(500.0) < contacts.screw_roller.max_pressure_pa(500.0)


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_load_from_approach_is_the_three_halves_power_down_to_tiny_approaches(name: str) -> None:
    """Q = (delta / K_h)^(3/2) (004 eq. 19 inverted) holds at every approach above zero, down
    to the nanometres of a contact that just touches: the load distribution relies on it being
    smooth through loss of contact (docs/physics.md). A mutation review found it unguarded
    below the round trip's 1 N."""
    pair = thread_contacts(load_preset(name).geometry).screw_roller
    approaches = np.geomspace(1e-12, 1e-5, 15)
    expected = (approaches / pair.deflection_constant) ** 1.5
    np.testing.assert_allclose(pair.load_n(approaches), expected, rtol=1e-12)
    np.testing.assert_allclose(pair.load_n(4.0 * approaches), 8.0 * expected, rtol=1e-12)
