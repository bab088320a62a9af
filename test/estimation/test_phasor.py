"""Local polar coordinates of the ripple phasor (estimation/phasor.py)."""

from __future__ import annotations

import math

import numpy as np

from prsm_health.estimation.measurement import RIPPLE, RIPPLE_COS, RIPPLE_SIN
from prsm_health.estimation.phasor import SMALLEST_AMPLITUDE, polar_about


def state(c: float, s: float) -> tuple[np.ndarray, np.ndarray]:
    """A state with load 30 kN, the phasor (c, s), and a covariance correlating them."""
    x = np.array([30e3, 100.0, 0.0, c, s])
    rng = np.random.default_rng(3)
    root = rng.normal(size=(5, 5)) * np.array([500.0, 1e3, 1e4, 0.05, 0.05])[:, None]
    return x, root @ root.T + np.diag([1e4, 1e4, 1e6, 1e-4, 1e-4])


def test_the_round_trip_at_the_linearisation_point_changes_nothing() -> None:
    x, p = state(0.2, -0.15)
    polar = polar_about(x)
    assert polar is not None
    xp, pp = polar.to_polar(x, p)
    assert xp[RIPPLE_COS] == math.hypot(0.2, -0.15) and xp[RIPPLE_SIN] == 0.0
    back, p_back = polar.to_cartesian(xp, pp)
    np.testing.assert_allclose(back, x, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(p_back, p, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(pp, pp.T)
    assert np.all(np.linalg.eigvalsh(pp) > 0.0)


def test_the_phase_keeps_its_uncertainty_when_the_amplitude_shrinks() -> None:
    """Across the phasor (c, s) holds amplitude x phase uncertainty: a phasor of 0.3 with its
    phase known to 0.1 rad, shrunk to 0.05 in polar coordinates, comes back with 0.005 across
    it, where a linear filter over (c, s) would have kept 0.03."""
    x = np.array([30e3, 0.0, 0.0, 0.0, 0.3])
    p = np.diag([1e4, 1e4, 1e6, 0.03**2, 0.02**2])  # across (c) 0.03 = 0.3 x 0.1 rad, along 0.02
    polar = polar_about(x)
    assert polar is not None
    xp, pp = polar.to_polar(x, p)
    assert math.isclose(math.sqrt(pp[RIPPLE_SIN, RIPPLE_SIN]), 0.1)
    xp[RIPPLE_COS] = 0.05
    back, p_back = polar.to_cartesian(xp, pp)
    np.testing.assert_allclose(back[RIPPLE], [0.0, 0.05], atol=1e-15)
    assert math.isclose(math.sqrt(p_back[RIPPLE_COS, RIPPLE_COS]), 0.005)
    assert math.isclose(math.sqrt(p_back[RIPPLE_SIN, RIPPLE_SIN]), 0.02)


def test_the_jacobian_maps_a_measurement_onto_amplitude_and_phase() -> None:
    """h = a c + b s: d h / d rho = (a, b) . u and d h / d delta = rho (a, b) . v, checked
    against finite differences of h at the Cartesian state."""
    x, _ = state(-0.1, 0.25)
    polar = polar_about(x)
    assert polar is not None
    xp, _ = polar.to_polar(x, np.eye(5))
    xp[RIPPLE_SIN] = 0.2  # away from the linearisation point
    jacobian = np.array([0.0, 0.0, 0.0, 1.5, -0.7])

    def h(polar_state: np.ndarray) -> float:
        return float(jacobian @ polar.cartesian_state(polar_state))

    mapped = polar.polar_jacobian(xp, jacobian)
    for index in (RIPPLE_COS, RIPPLE_SIN):
        step = np.zeros(5)
        step[index] = 1e-7
        numeric = (h(xp + step) - h(xp - step)) / 2e-7
        assert math.isclose(mapped[index], numeric, rel_tol=1e-6)


def test_a_phasor_without_length_has_no_polar_coordinates() -> None:
    assert polar_about(np.array([1.0, 0.0, 0.0, 0.0, 0.0])) is None
    assert polar_about(np.array([1.0, 0.0, 0.0, 0.5 * SMALLEST_AMPLITUDE, 0.0])) is None
    assert polar_about(np.array([1.0, 0.0, 0.0, 2.0 * SMALLEST_AMPLITUDE, 0.0])) is not None
