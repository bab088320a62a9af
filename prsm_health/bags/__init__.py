"""Reading and writing rosbag2 MCAP bags with rosbags and numpy (no rclpy): docs/bags.md.

- :mod:`~prsm_health.bags.typestore`: the Jazzy type store with our messages, type names
  (``typestore()`` is not re-exported here: it would hide its module).
- :mod:`~prsm_health.bags.writer`: :class:`BagWriter` and ``write_*`` for whole series.
- :mod:`~prsm_health.bags.reader`: :class:`InputTopics`, ``iter/read_motor_samples``,
  ``read_truth``, tolerant of damaged bags.
- :mod:`~prsm_health.bags.baseline`: the rosbags decode time, the replay's speed floor.
- Inside: :mod:`~prsm_health.bags.stamps` (time conventions), :mod:`~prsm_health.bags.codecs`
  and :mod:`~prsm_health.bags.cdr` (vectorised CDR), :mod:`~prsm_health.bags.mcap_scan`
  (MCAP scanning), :mod:`~prsm_health.bags.bagfiles` (bag directory layout).
"""

from prsm_health.bags.baseline import Baseline, decode_baseline, decode_time_baseline
from prsm_health.bags.errors import (
    BagDamagedError,
    BagError,
    InterfaceNotFoundError,
    TopicNotFoundError,
)
from prsm_health.bags.reader import InputTopics, iter_motor_samples, read_motor_samples, read_truth
from prsm_health.bags.typestore import (
    DIAGNOSTIC_ARRAY,
    GROUND_TRUTH,
    HEALTH_ESTIMATE,
    JOINT_STATE,
    MOTOR_STATE,
)
from prsm_health.bags.writer import (
    BagWriter,
    write_joint_states,
    write_motor_states,
    write_truth,
)

__all__ = [
    "DIAGNOSTIC_ARRAY",
    "GROUND_TRUTH",
    "HEALTH_ESTIMATE",
    "JOINT_STATE",
    "MOTOR_STATE",
    "BagDamagedError",
    "BagError",
    "BagWriter",
    "Baseline",
    "InputTopics",
    "InterfaceNotFoundError",
    "TopicNotFoundError",
    "decode_baseline",
    "decode_time_baseline",
    "iter_motor_samples",
    "read_motor_samples",
    "read_truth",
    "write_joint_states",
    "write_motor_states",
    "write_truth",
]
