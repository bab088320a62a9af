"""Test-wide setup: DDS isolation before anything imports rclpy."""

from __future__ import annotations

import os
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _domain_id() -> int:
    """A ROS domain in 1..101 of our own: per xdist worker, else per process."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    if worker.startswith("gw"):
        return 1 + (os.getppid() + int(worker[2:])) % 101
    return 1 + os.getpid() % 101


os.environ.setdefault("ROS_DOMAIN_ID", str(_domain_id()))
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ["FASTDDS_BUILTIN_TRANSPORTS"] = "UDPv4"
os.environ.setdefault("ROS_LOG_DIR", str(REPO / "build" / "ros_log"))
