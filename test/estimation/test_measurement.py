"""The measurement model (prsm_health/estimation/measurement.py) against its own documented
relations."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from prsm_health.actuator import Actuator
from prsm_health.estimation.inputs import Block
from prsm_health.estimation.measurement import LOAD, LOAD_ACCELERATION, Prediction, TorqueModel
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


@pytest.mark.parametrize("jammed", [0, 1])
def test_a_block_releasing_the_load_is_predicted_at_its_mean_load(jammed: int) -> None:
    """The block's torque is a mean over its samples: under a load accelerating at F'' the
    block carries F + F'' var(t) / 2 on average about its mean stamp, not F (a release of
    45 kN in 0.2 s bends the load by 370 N within a 40 ms block). With
    ``model.load_transition_acceleration_rad_s2`` set, a block decelerating faster is
    predicted at load F and acceleration F'' as at load F + F'' var / 2 without acceleration,
    and its Jacobian's acceleration entry is its load entry times var / 2. Without the
    setting, or below it, the load's acceleration does not enter (docs/estimation.md, "A load
    released fast")."""
    released = dataclasses.replace(
        PARAMS, model=dataclasses.replace(PARAMS.model, load_transition_acceleration_rad_s2=200.0)
    )
    model = TorqueModel(released)
    variance, load, acceleration = 1.3e-4, 20_000.0, -5.0e6
    decelerating = dataclasses.replace(
        MOVING, stamp_var_s2=variance, motor_acceleration_rad_s2=-800.0
    )
    x = np.zeros(model.dim)
    x[LOAD], x[LOAD_ACCELERATION] = load, acceleration
    mean_load = load + 0.5 * variance * acceleration
    assert mean_load == pytest.approx(19_675.0)
    straight = x.copy()
    straight[LOAD], straight[LOAD_ACCELERATION] = mean_load, 0.0
    bent = model.predict(x, decelerating, jammed)
    expected = model.predict(straight, decelerating, jammed)
    assert bent.motor_torque_nm == pytest.approx(expected.motor_torque_nm, rel=1e-12)
    assert bent.jacobian[LOAD] == pytest.approx(expected.jacobian[LOAD], rel=1e-12)
    assert bent.jacobian[LOAD_ACCELERATION] == pytest.approx(
        expected.jacobian[LOAD] * 0.5 * variance, rel=1e-12
    )
    flat = x.copy()
    flat[LOAD_ACCELERATION] = 0.0
    for unbent_model, block in (
        (MODEL, decelerating),
        (model, dataclasses.replace(decelerating, motor_acceleration_rad_s2=-150.0)),
    ):
        unbent = unbent_model.predict(x, block, jammed)
        assert unbent.jacobian[LOAD_ACCELERATION] == 0.0
        at_load_f = unbent_model.predict(flat, block, jammed)
        assert unbent.motor_torque_nm == pytest.approx(at_load_f.motor_torque_nm, rel=1e-12)
        assert unbent.motor_torque_nm != pytest.approx(bent.motor_torque_nm, rel=1e-3)
