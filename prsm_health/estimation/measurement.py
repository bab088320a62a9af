"""The measurement model: the motor torque a block should show, given the state and a jam count.

State x = [F, dF/dt, d2F/dt2] or, with the ripple terms, [F, dF/dt, d2F/dt2, c, s]: the
signed axial load F (> 0 resists positive rotation) and its first two derivatives, and the
carrier-frequency ripple of the jammed rollers, c cos(theta) + s sin(theta) (theta the carrier
angle from the motor position), relative to a load-dependent scale S(F) that grows with |F| and
saturates (RIPPLE_KNEE_FRACTION). With k jammed rollers, a block moving in direction d = +-1
at screw speed w:

    T_screw = F L/2pi + d (M_k(|F|, |w|) + S(F) (c <cos theta> + s <sin theta>))
                                                                    (002 eq. 12-19, lead L)
    T_motor = J_total alpha + (T_screw + d (1 - eta_g)/eta_g |T_screw|) / G    (actuator.py)

with M_k of :mod:`prsm_health.estimation.surrogate` and <.> the block means. At standstill
(d = 0) friction can hold anything between -M_static and +M_static (stiction), so T_screw =
F L / 2 pi + u with u uniform on that band: its variance M_static^2 / 3 joins the measurement
noise and the block carries no evidence about jams (docs/estimation.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from prsm_health.estimation.inputs import Block
from prsm_health.estimation.params import EstimatorParams
from prsm_health.estimation.surrogate import (
    DAMAGE,
    ROLLING,
    SLIDING,
    VISCOUS,
    WEAR_HEALTHY,
    WEAR_JAMMED,
    AverageModel,
    DirectPhysics,
    averaged_tables,
    jammed_ripple_nm_per_n,
)
from prsm_health.physics.friction import VISCOUS_SPEED_EXPONENT
from prsm_health.physics.load_distribution import LoadingCase

FloatArray = NDArray[np.float64]

#: State layout: the load and its first two derivatives, then the ripple (when modelled).
LOAD, LOAD_RATE, LOAD_ACCELERATION, RIPPLE_COS, RIPPLE_SIN = range(5)
LOAD_STATES = 3
#: The ripple phasor (c, s) in the state.
RIPPLE = slice(RIPPLE_COS, RIPPLE_SIN + 1)

#: The ripple grows with the load up to this fraction of the load scale
#: (EstimatorParams.load_scale_n) and stays at its size beyond: a jammed roller's ripple comes
#: from the radial load (the borehole wall, 000) or the misalignment (004), which do not grow
#: with the axial load, but the loaded flank can only carry a radial load below about the
#: axial load (load_distribution.radial_capacity_ratio), so it vanishes with the axial load.
#: scale = |F| L/2pi / sqrt(1 + (F / knee)^2).
RIPPLE_KNEE_FRACTION = 0.2
#: Below this fraction of the load scale (EstimatorParams.load_scale_n) the friction's slope
#: takes the resisting side.
KINK_FRACTION = 1e-2


@dataclass(frozen=True)
class Prediction:
    """What hypothesis k predicts for one block at state x.

    motor_torque_nm and jacobian (d/dx, one row) of the measurement; variance_nm2 of the
    measurement noise (sensors, model error, stiction band); friction_torque_nm (magnitude;
    the breakaway band at standstill); precision_loss_rate_m_per_s and fatigue_rate_per_s,
    with their derivatives d/d|F|. self_locking: at standstill, the stiction band grows
    faster with |F| than the load torque F L/2pi (three or more jammed rollers of the downhole
    preset): any load the band holds explains a held torque.
    """

    motor_torque_nm: float
    jacobian: FloatArray
    variance_nm2: float
    friction_torque_nm: float
    precision_loss_rate_m_per_s: float
    precision_loss_rate_slope: float
    fatigue_rate_per_s: float
    fatigue_rate_slope: float
    self_locking: bool = False


class TorqueModel:
    """Measurement model of every jam hypothesis (see the module docstring)."""

    def __init__(self, params: EstimatorParams) -> None:
        actuator = params.actuator
        preset = actuator.preset
        drive = actuator.drive_train
        self.n_rollers = preset.geometry.n_rollers
        self.ripple = params.radial_terms
        self.dim = RIPPLE_SIN + 1 if self.ripple else LOAD_STATES
        self._load_arm_m = preset.geometry.lead_m / (2.0 * math.pi)
        self._gear_ratio = drive.gear_ratio
        self._gear_loss = (1.0 - drive.gear_efficiency) / drive.gear_efficiency
        self._inertia = drive.inertia_at_motor_kg_m2
        self._ripple_knee_n = RIPPLE_KNEE_FRACTION * params.load_scale_n
        self._ripple_per_radial_n = jammed_ripple_nm_per_n(preset) / (
            self._ripple_knee_n * self._load_arm_m
        )
        self._kink_n = KINK_FRACTION * params.load_scale_n
        self._wear_scale = actuator.wear_acceleration * params.model.wear_coefficient_factor
        self._actuator = actuator
        self._model_params = params.model
        noise = params.noise
        self._torque_constant = drive.torque_constant_nm_per_a
        self._current_var = noise.current_std_a**2
        self._model_rel = noise.model_error_rel
        self._model_floor_var = noise.model_error_floor_nm**2
        ratio = params.model.radial_load_ratio if params.radial_terms else 0.0
        self._models: dict[LoadingCase, AverageModel] = {}
        for case in LoadingCase:
            if params.fidelity.surrogate:
                self._models[case] = averaged_tables(preset, actuator.misalignment, ratio, case)
            else:
                self._models[case] = DirectPhysics(preset, actuator.misalignment, ratio, case)

    def ripple_scale(self, load_n: float) -> tuple[float, float]:
        """S(F) = |F| L/2pi / sqrt(1 + (F / knee)^2) and dS/dF (see RIPPLE_KNEE_FRACTION)."""
        root = math.sqrt(1.0 + (load_n / self._ripple_knee_n) ** 2)
        return (
            abs(load_n) * self._load_arm_m / root,
            math.copysign(self._load_arm_m, load_n) / root**3,
        )

    def ripple_relative(self, radial_load_n: float) -> float:
        """The size of the ripple phasor (c, s: relative to the load torque at the knee, S(F)
        saturated) that ``radial_load_n`` of radial load makes with one jammed roller
        (:func:`~prsm_health.estimation.surrogate.jammed_ripple_nm_per_n`): the parameters
        give the ripple's prior and walks as radial loads."""
        return self._ripple_per_radial_n * radial_load_n

    def predict(self, x: FloatArray, block: Block, jammed: int) -> Prediction:
        """The measurement of ``block`` under ``jammed`` rollers at state ``x``."""
        # The block's torque is a mean over its samples, and so is the load it carries: under
        # the constant-acceleration load model, F + F'' var(t) / 2 about the mean stamp. Only
        # where the load is released fast (the model's setting): elsewhere the load bends too
        # little within a block for its uncertain F'' to pay (docs/estimation.md, "A load
        # released fast").
        curvature_weight = 0.0
        if self._model_params.releases_load(block.motor_acceleration_rad_s2):
            curvature_weight = 0.5 * block.stamp_var_s2
        load = float(x[LOAD]) + curvature_weight * float(x[LOAD_ACCELERATION])
        direction = block.direction
        case = self._actuator.loading_case(block.motor_speed_rad_s)
        # Python floats: the arithmetic below is scalar, where numpy's scalars are slow.
        value, slope = (array.tolist() for array in self._models[case].evaluate(load))
        healthy = self.n_rollers - jammed
        screw_speed = abs(block.motor_speed_rad_s) / self._gear_ratio
        jacobian = np.zeros(self.dim)
        static = healthy * value[ROLLING] + jammed * value[SLIDING]
        if direction:
            speed_factor = screw_speed**VISCOUS_SPEED_EXPONENT
            friction = static + healthy * value[VISCOUS] * speed_factor
            friction_slope = (
                healthy * (slope[ROLLING] + slope[VISCOUS] * speed_factor) + jammed * slope[SLIDING]
            )
            screw_torque = load * self._load_arm_m + direction * friction
            # Friction depends on |F|: its slope changes sign with F. Near F = 0 the resisting
            # side is taken (F d > 0): with three or more jammed rollers the friction per
            # newton exceeds the load arm, and an assisting load of a self-locked screw needs
            # the same motor torque as a smaller resisting one; the common case wins there.
            side = load if abs(load) > self._kink_n else float(direction)
            d_screw_d_load = self._load_arm_m + direction * math.copysign(friction_slope, side)
            band_var, self_locking = 0.0, False
            if self.ripple and jammed:
                # The ripple scales with the load torque: c, s are relative amplitudes.
                relative = float(
                    x[RIPPLE_COS] * block.carrier_cos + x[RIPPLE_SIN] * block.carrier_sin
                )
                scale, d_scale = self.ripple_scale(load)
                screw_torque += direction * scale * relative
                d_screw_d_load += direction * d_scale * relative
                jacobian[RIPPLE_COS] = direction * scale * block.carrier_cos
                jacobian[RIPPLE_SIN] = direction * scale * block.carrier_sin
        else:
            friction = static
            screw_torque = load * self._load_arm_m
            d_screw_d_load = self._load_arm_m
            band_var = static**2 / 3.0
            static_slope = healthy * slope[ROLLING] + jammed * slope[SLIDING]
            self_locking = static_slope >= self._load_arm_m
        gear = (
            1.0 + direction * self._gear_loss * math.copysign(1.0, screw_torque)
        ) / self._gear_ratio
        motor_torque = self._inertia * block.motor_acceleration_rad_s2 + gear * screw_torque
        jacobian[LOAD] = gear * d_screw_d_load
        jacobian[LOAD_ACCELERATION] = jacobian[LOAD] * curvature_weight
        jacobian[RIPPLE_COS:] *= gear
        variance = (
            self._torque_constant**2
            * max(self._current_var, block.current_residual_var_a2)
            / block.samples
            + self._inertia**2 * block.motor_acceleration_var_rad2_s4
            + (self._model_rel * motor_torque) ** 2
            + self._model_floor_var
            + gear**2 * band_var
        )
        wear_per_rad = healthy * value[WEAR_HEALTHY] + jammed * value[WEAR_JAMMED]
        wear_slope = healthy * slope[WEAR_HEALTHY] + jammed * slope[WEAR_JAMMED]
        wear_speed = screw_speed * self._wear_scale if direction else 0.0
        fatigue_speed = screw_speed if direction else 0.0
        return Prediction(
            motor_torque_nm=motor_torque,
            jacobian=jacobian,
            variance_nm2=variance,
            friction_torque_nm=friction,
            precision_loss_rate_m_per_s=wear_speed * wear_per_rad,
            precision_loss_rate_slope=wear_speed * wear_slope,
            fatigue_rate_per_s=fatigue_speed * value[DAMAGE],
            fatigue_rate_slope=fatigue_speed * slope[DAMAGE],
            self_locking=self_locking,
        )
