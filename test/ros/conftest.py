"""rclpy for the node tests' listener (the DDS environment is set by test/conftest.py)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
import rclpy


@pytest.fixture(scope="session")
def ros() -> Iterator[None]:
    """rclpy initialised in the test process for the whole session."""
    rclpy.init()
    yield
    rclpy.try_shutdown()
