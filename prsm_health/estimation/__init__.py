"""The ROS-free health estimator (docs/estimation.md).

From Python, the same as the replay and the node::

    from prsm_health.estimation import HealthEstimator, load_params
    from prsm_health.signals import MotorSamples

    estimator = HealthEstimator(load_params("config/default.yaml"))
    states = estimator.process(MotorSamples(stamp_s, current_a, speed_rad_s, position_rad))
    states += estimator.finish()  # at the end of the data: the blocks still pending
"""

from prsm_health.estimation.estimate import EstimateEvent, HealthState
from prsm_health.estimation.estimator import HealthEstimator
from prsm_health.estimation.params import EstimatorParams, bundled_params_file, load_params

__all__ = [
    "EstimateEvent",
    "EstimatorParams",
    "HealthEstimator",
    "HealthState",
    "bundled_params_file",
    "load_params",
]
