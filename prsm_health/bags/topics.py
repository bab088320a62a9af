"""Default topic names of this package's bags and live topics.

``/motor_state`` (prsm_health_msgs/MotorState) is the estimator's input, ``/joint_states``
(sensor_msgs/JointState) the alternative input, ``/truth/state`` (prsm_health_msgs/GroundTruth)
the simulator's ground truth, ``/prsm_health/health`` (HealthEstimate, the node's ``~/health``)
and ``/diagnostics``
(diagnostic_msgs/DiagnosticArray) the estimator's outputs.
"""

from __future__ import annotations

MOTOR_STATE_TOPIC = "/motor_state"
JOINT_STATES_TOPIC = "/joint_states"
TRUTH_TOPIC = "/truth/state"
HEALTH_TOPIC = "/prsm_health/health"
DIAGNOSTICS_TOPIC = "/diagnostics"

#: Frame of MotorState headers, and name of the motor joint in JointState messages.
MOTOR_FRAME = "prsm_motor"
