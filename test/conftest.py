"""Test-wide setup: DDS isolation before anything imports rclpy, and no state in the home."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _set_domain_id() -> None:
    """A ROS domain in 1..101 of our own: per process, unless ROS_DOMAIN_ID is set; per worker
    under pytest-xdist (``-n``), whatever is set. A worker inherits the environment of the
    controlling process, to which this module has already given its domain: kept, it put
    both workers in one (measured on 2026-11-29: both read 50)."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    if worker.startswith("gw"):
        os.environ["ROS_DOMAIN_ID"] = str(1 + (os.getppid() + int(worker[2:])) % 101)
    else:
        os.environ.setdefault("ROS_DOMAIN_ID", str(1 + os.getpid() % 101))


_set_domain_id()
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ["FASTDDS_BUILTIN_TRANSPORTS"] = "UDPv4"
os.environ.setdefault("ROS_LOG_DIR", str(REPO / "build" / "ros_log"))


@pytest.fixture(autouse=True, scope="session")
def _state_home(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """A node started without ``state_file`` saves in ``$XDG_STATE_HOME`` (the user's
    ``~/.local/state`` when unset): point it into the session's temporary tree, for this
    process and the nodes it starts, so that no test writes there or resumes what an earlier
    run saved."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("XDG_STATE_HOME", str(tmp_path_factory.mktemp("state_home")))
        yield
