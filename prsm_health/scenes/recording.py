"""Recording a simulated run as a rosbag2 MCAP bag (``prsm-health simulate``).

Topics: ``/motor_state`` (prsm_health_msgs/MotorState, the estimator's input; log time = the
simulated receive time), optionally ``/joint_states`` (sensor_msgs/JointState with
effort = motor current [A]; log time from the stamps) and ``/truth/state``
(prsm_health_msgs/GroundTruth at the scene's truth rate). Stamps count from the scene start
(the bag starts at the epoch). The run is written chunk by chunk, so hours-long scenes stream;
the bag bytes depend only on the scene, its seed and the chunk size (fixed here), never on the
machine or the time of day.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path

import numpy as np

from prsm_health.bags.writer import BagWriter, write_joint_states, write_motor_states, write_truth
from prsm_health.scenes.simulator import DEFAULT_CHUNK_SAMPLES, Simulator

NS_PER_S = 1_000_000_000


def record(
    simulator: Simulator,
    path: Path,
    *,
    progress: Callable[[int], None] | None = None,
    stop: threading.Event | None = None,
) -> tuple[int, int]:
    """Simulate ``simulator``'s scene into the new bag directory ``path``.

    ``progress`` is called with the number of samples simulated after every chunk. When
    ``stop`` is set, the recording ends after the chunk being written, and the bag is closed
    as a complete (shorter) bag. Returns the numbers of motor and truth messages written.
    """
    scene = simulator.scene
    motor_count = truth_count = 0
    with BagWriter(path) as writer:
        remaining = scene.samples
        for chunk in simulator.run(DEFAULT_CHUNK_SAMPLES):
            receive_ns = np.round(chunk.receive_time_s * NS_PER_S).astype(np.int64)
            write_motor_states(writer, chunk.motor, receive_time_ns=receive_ns)
            if scene.joint_states:
                write_joint_states(writer, chunk.motor)
            write_truth(writer, chunk.truth)
            motor_count += len(chunk.motor)
            truth_count += len(chunk.truth)
            done = min(DEFAULT_CHUNK_SAMPLES, remaining)
            remaining -= done
            if progress is not None:
                progress(done)
            if stop is not None and stop.is_set():
                break
    return motor_count, truth_count
