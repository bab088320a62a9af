"""The type store: our messages from the installed .msg files, found without rclpy."""

from __future__ import annotations

import importlib.util
import json
import shutil
from pathlib import Path

import pytest

from prsm_health.bags.errors import InterfaceNotFoundError
from prsm_health.bags.typestore import (
    DIAGNOSTIC_ARRAY,
    GROUND_TRUTH,
    HEALTH_ESTIMATE,
    JOINT_STATE,
    MOTOR_STATE,
    OWN_TYPES,
    find_msg_dir,
    typestore,
)


def test_store_has_our_types_and_the_jazzy_ones() -> None:
    store = typestore()
    for name in (MOTOR_STATE, HEALTH_ESTIMATE, GROUND_TRUTH, JOINT_STATE, DIAGNOSTIC_ARRAY):
        assert name in store.types
    assert typestore() is store  # cached


def test_hashes_equal_the_ones_rosidl_generated() -> None:
    """rosbags' RIHS01 of each registered type equals the hash in the installed .json."""
    folder = find_msg_dir()
    for name in OWN_TYPES:
        described = json.loads((folder / f"{name.rsplit('/', 1)[1]}.json").read_text())
        expected = next(h for h in described["type_hashes"] if h["type_name"] == name)
        assert typestore().hash_rihs01(name) == expected["hash_string"]


def test_found_beside_the_installed_python_package(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    spec = importlib.util.find_spec("prsm_health_msgs")
    assert spec is not None and spec.origin is not None
    folder = find_msg_dir()
    assert folder.parts[-3:] == ("share", "prsm_health_msgs", "msg")
    assert Path(spec.origin).resolve().is_relative_to(folder.parents[2])


def test_ament_prefix_path_comes_first(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    prefix = tmp_path / "install"
    shutil.copytree(find_msg_dir(), prefix / "share" / "prsm_health_msgs" / "msg")
    monkeypatch.setenv("AMENT_PREFIX_PATH", f"{tmp_path / 'empty'}:{prefix}")
    assert find_msg_dir() == prefix / "share" / "prsm_health_msgs" / "msg"


def test_not_installed_is_a_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("AMENT_PREFIX_PATH", "/nonexistent/prefix")
    monkeypatch.setattr(importlib.util, "find_spec", lambda name: None)
    with pytest.raises(
        InterfaceNotFoundError, match=r"prsm_health_msgs is not installed.*make venv"
    ):
        find_msg_dir()
