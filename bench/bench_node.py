"""Throughput and latency of prsm_health_node at 1 kHz over Fast DDS (a benchmark, not a test).

Three processes on loopback (the DDS rules of shared/ROS_PIP.md, ROS_DOMAIN_ID 43 unless set):
the node (``python -m prsm_health.ros.node``, default parameters, a throw-away state file);
a publisher process sending ``MotorState`` at ``--rate-hz`` (default 1000) for ``--seconds``,
stamped with the wall clock at publish time; and this process, which receives
``/prsm_health/health`` and ``/diagnostics``.

Reports: messages dropped (published minus what the node's input-health status says it
received, after the run; floor 0 at 1 kHz on 2 cores); the median and p99 latency from the
header stamp of the last sample of a block to the arrival of that block's HealthEstimate here
(both on the wall clock of this machine); the node's CPU use in cores; and its resident
memory (VmRSS), sampled once a second while the samples flow: as they start (the node up and
active), at the end, and its growth per hour, the slope of a straight line through the second
half of the run (the first half holds the warm-up: filters allocated, buffers grown), which a
leak keeps above zero (null for a run shorter than about 8 s).

    .venv/bin/python bench/bench_node.py [--seconds 20] [--rate-hz 1000] [--batch-period-s S]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from prsm_health.ros.runtime import loopback_env

BLOCK_S = 0.04  # the estimator's default block duration (filter.block_duration_s)
CLOCK_TICKS = os.sysconf("SC_CLK_TCK")

PUBLISHER = """
import json, math, sys, time
import numpy as np
import rclpy
from prsm_health_msgs.msg import MotorState
rate_hz, seconds, out = float(sys.argv[1]), float(sys.argv[2]), sys.argv[3]
rclpy.init()
node = rclpy.create_node("bench_publisher")
from rclpy.qos import qos_profile_sensor_data
pub = node.create_publisher(MotorState, "motor_state", qos_profile_sensor_data)
deadline = time.monotonic() + 10.0
while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
    time.sleep(0.01)
time.sleep(0.3)
rng = np.random.default_rng(0)
n = int(rate_hz * seconds)
speed = 300.0 * math.pi / 30.0 * 5.0  # 300 rpm screw behind the 5:1 gearbox
current, speed_noise = 7.3 + rng.normal(0, 0.05, n), speed + rng.normal(0, 0.2, n)
stamps = np.empty(n)
msg = MotorState()
start = time.monotonic()
for i in range(n):
    delay = start + i / rate_hz - time.monotonic()
    if delay > 0:
        time.sleep(delay)
    now = time.time()
    stamps[i] = now
    msg.header.stamp.sec = int(now)
    msg.header.stamp.nanosec = int((now - int(now)) * 1e9)
    msg.current_a = float(current[i])
    msg.speed_rad_s = float(speed_noise[i])
    msg.position_rad = speed * i / rate_hz
    pub.publish(msg)
np.save(out, stamps)
time.sleep(0.5)
node.destroy_node()
rclpy.shutdown()
"""


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process so far [s]."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLOCK_TICKS


def resident_mib(pid: int) -> float:
    """Resident memory of a process (VmRSS) [MiB]."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    raise RuntimeError(f"no VmRSS for process {pid}")


#: Fewest readings in the second half for a growth figure (a shorter run gives None).
MIN_GROWTH_READINGS = 4


def growth_mib_per_h(samples: list[tuple[float, float]]) -> float | None:
    """Slope of a least-squares line through the second half of (time [s], MiB) [MiB/h];
    None with fewer than MIN_GROWTH_READINGS readings there."""
    half = samples[len(samples) // 2 :]
    if len(half) < MIN_GROWTH_READINGS:
        return None
    times, mib = np.asarray(half).T
    return float(np.polyfit(times, mib, 1)[0] * 3600.0)


def latencies(stamps: np.ndarray, received: list[tuple[float, float]]) -> np.ndarray:
    """Arrival time minus the stamp of the last sample of each estimate's block [s]."""
    anchor = stamps[0]
    cells = np.floor((stamps - anchor) / BLOCK_S).astype(np.int64)
    last = {int(c): float(t) for c, t in zip(cells, stamps, strict=True)}  # later wins
    out = []
    for arrival, block_stamp in received:
        cell = math.floor((block_stamp - anchor) / BLOCK_S)
        if cell in last:
            out.append(arrival - last[cell])
    return np.asarray(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--rate-hz", type=float, default=1000.0)
    parser.add_argument("--batch-period-s", type=float, default=None)
    args = parser.parse_args()
    os.environ.update(loopback_env(os.environ, 43))

    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from prsm_health_msgs.msg import HealthEstimate
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, QoSReliabilityPolicy

    from prsm_health.outputs import INPUT_HEALTH

    with tempfile.TemporaryDirectory() as tmp:
        node_args = ["-p", f"state_file:={tmp}/state.json"]
        if args.batch_period_s is not None:
            node_args += ["-p", f"batch_period_s:={args.batch_period_s}"]
        node = subprocess.Popen(  # noqa: S603 - our own interpreter and module
            [sys.executable, "-m", "prsm_health.ros.node", "--ros-args", *node_args]
        )
        rclpy.init()
        listener = rclpy.create_node("bench_listener")
        received: list[tuple[float, float]] = []
        inputs: dict[str, str] = {}

        def on_health(msg: Any) -> None:
            stamp = msg.header.stamp
            received.append((time.time(), stamp.sec + stamp.nanosec * 1e-9))

        def on_diagnostics(msg: Any) -> None:
            for status in msg.status:
                if status.name == INPUT_HEALTH:
                    inputs.update({kv.key: kv.value for kv in status.values})

        qos = QoSProfile(depth=100, reliability=QoSReliabilityPolicy.RELIABLE)
        listener.create_subscription(HealthEstimate, "/prsm_health/health", on_health, qos)
        listener.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, qos)
        executor = SingleThreadedExecutor()
        executor.add_node(listener)
        try:
            deadline = time.monotonic() + 30.0
            while not inputs and time.monotonic() < deadline:  # the node is up and active
                executor.spin_once(timeout_sec=0.05)
            stamps_file = f"{tmp}/stamps.npy"
            cpu_start = cpu_seconds(node.pid)
            wall_start = time.monotonic()
            publisher = subprocess.Popen(  # noqa: S603 - our own interpreter and script
                [sys.executable, "-c", PUBLISHER, str(args.rate_hz), str(args.seconds), stamps_file]
            )
            memory = [(0.0, resident_mib(node.pid))]
            while publisher.poll() is None:
                executor.spin_once(timeout_sec=0.05)
                elapsed = time.monotonic() - wall_start
                if elapsed >= memory[-1][0] + 1.0:
                    memory.append((elapsed, resident_mib(node.pid)))
            cpu = (cpu_seconds(node.pid) - cpu_start) / (time.monotonic() - wall_start)
            end = time.monotonic() + 2.5  # the node's next diagnostics, after the last sample
            while time.monotonic() < end:
                executor.spin_once(timeout_sec=0.05)
        finally:
            node.send_signal(2)
            node.wait(15)
            listener.destroy_node()
            rclpy.shutdown()
        stamps = np.load(stamps_file)
        lat = latencies(stamps, received) * 1e3
        growth = growth_mib_per_h(memory)
        report = {
            "published": len(stamps),
            "received_by_node": int(inputs.get("received", "-1")),
            "dropped": len(stamps) - int(inputs.get("received", "-1")),
            "estimates": len(received),
            "latency_median_ms": round(float(np.median(lat)), 2),
            "latency_p99_ms": round(float(np.percentile(lat, 99)), 2),
            "latency_max_ms": round(float(lat.max()), 2),
            "node_cpu_cores": round(cpu, 2),
            "node_rss_start_mib": round(memory[0][1], 1),
            "node_rss_end_mib": round(memory[-1][1], 1),
            "node_rss_growth_mib_per_h": None if growth is None else round(growth, 2),
        }
        print(json.dumps(report))


if __name__ == "__main__":
    main()
