"""The measurement model (prsm_health/estimation/measurement.py) against its own documented
relations."""

from __future__ import annotations

import numpy as np
import pytest

from prsm_health.actuator import Actuator
from prsm_health.estimation.inputs import Block
from prsm_health.estimation.measurement import LOAD, Prediction, TorqueModel
from prsm_health.estimation.params import EstimatorParams
from prsm_health.physics.presets import load_preset

PARAMS = EstimatorParams(actuator=Actuator(preset=load_preset("dong2022-downhole")))
MODEL = TorqueModel(PARAMS)
MOVING = Block(
    stamp_s=0.0,
    duration_s=0.04,
    samples=40,
    motor_torque_nm=0.0,
    motor_speed_rad_s=150.0,
    motor_acceleration_rad_s2=0.0,
    carrier_cos=1.0,
    carrier_sin=0.0,
    direction=1,
)


def at_load(load_n: float, jammed: int) -> Prediction:
    """The prediction for the moving block at ``load_n`` with ``jammed`` rollers."""
    x = np.zeros(MODEL.dim)
    x[LOAD] = load_n
    return MODEL.predict(x, MOVING, jammed)


@pytest.mark.parametrize("jammed", [0, 2])
def test_the_degradation_slopes_are_the_derivatives_of_the_rates(jammed: int) -> None:
    """precision_loss_rate_slope and fatigue_rate_slope are d/d|F| of their rates (the
    Prediction docstring; the degradation integrator turns them into the rates' uncertainty),
    for healthy and jammed rollers alike: pinned by a central difference. A mutation review
    found the jammed rollers' wear slope unguarded (the healthy rollers' slope in its place)."""
    load, step = 23_456.0, 1.0
    prediction = at_load(load, jammed)
    above, below = at_load(load + step, jammed), at_load(load - step, jammed)
    for rate, slope in (
        ("precision_loss_rate_m_per_s", "precision_loss_rate_slope"),
        ("fatigue_rate_per_s", "fatigue_rate_slope"),
    ):
        difference = (getattr(above, rate) - getattr(below, rate)) / (2 * step)
        assert difference > 0.0
        np.testing.assert_allclose(getattr(prediction, slope), difference, rtol=1e-4)
