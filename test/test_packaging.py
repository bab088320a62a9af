"""Packaging checks: the generated messages, their type hashes, and a colcon build."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

REPO = Path(__file__).resolve().parents[1]
MSG_DIR = REPO / "msg_defs" / "prsm_health_msgs" / "msg"
VENV = Path(sys.prefix)


def fresh_env(**extra: str) -> dict[str, str]:
    """Environment for a child that bootstraps the ROS wheels itself (see ROS_PIP.md)."""
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("_ROS_WHEELS_BOOTSTRAP_COMPLETE", "LD_LIBRARY_PATH")
    }
    env["PATH"] = f"{VENV / 'bin'}{os.pathsep}{env['PATH']}"
    env.update(extra)
    return env


def run(args: list[str], timeout: float, cwd: Path | None = None, **extra_env: str) -> str:
    """Run a child process; on failure show its output. Returns stdout."""
    proc = subprocess.run(
        args,
        env=fresh_env(**extra_env),
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )
    assert proc.returncode == 0, f"{args[0]} failed:\n{proc.stdout[-4000:]}\n{proc.stderr[-4000:]}"
    return proc.stdout


ROUNDTRIP = """
from rclpy.serialization import deserialize_message, serialize_message
from prsm_health_msgs.msg import HealthEstimate, MotorState

motor = MotorState(current_a=1.25, speed_rad_s=-3.5, position_rad=12.0)
motor.header.frame_id = "screw"
health = HealthEstimate(axial_load_n=1500.0, jammed_rollers_most_likely=1,
                        jammed_rollers_probability=[0.1, 0.8, 0.1], efficiency=0.85,
                        fatigue_damage=0.02)
for msg in (motor, health):
    assert deserialize_message(serialize_message(msg), type(msg)) == msg, msg
print("ok")
"""

TYPE_HASHES = """
import rclpy
from prsm_health_msgs.msg import GroundTruth, HealthEstimate, MotorState

rclpy.init()
node = rclpy.create_node("type_hash_probe")
for msg_type in (MotorState, HealthEstimate, GroundTruth):
    topic = "hash_" + msg_type.__name__
    node.create_publisher(msg_type, topic, 1)
    print(msg_type.__name__, node.get_publishers_info_by_topic(topic)[0].topic_type_hash)
node.destroy_node()
rclpy.shutdown()
"""


def test_messages_roundtrip_in_fresh_interpreter() -> None:
    assert run([sys.executable, "-c", ROUNDTRIP], timeout=60).strip() == "ok"


def test_type_hashes_match_rosbags() -> None:
    """RIHS01 hashes rosbags computes from the .msg text equal the ones the typesupport reports."""
    store = get_typestore(Stores.ROS2_JAZZY)
    expected = {}
    for name in ("MotorState", "HealthEstimate", "GroundTruth"):
        typename = f"prsm_health_msgs/msg/{name}"
        store.register(get_types_from_msg((MSG_DIR / f"{name}.msg").read_text(), typename))
        expected[name] = store.hash_rihs01(typename)

    out = run([sys.executable, "-c", TYPE_HASHES], timeout=60)
    reported = dict(line.split() for line in out.splitlines())
    assert reported == expected


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_colcon_build_installs_both_packages(tmp_path: Path) -> None:
    install = tmp_path / "install"
    run(
        [
            str(VENV / "bin" / "colcon"),
            "--log-base",
            str(tmp_path / "log"),
            "build",
            "--build-base",
            str(tmp_path / "build"),
            "--install-base",
            str(install),
            "--paths",
            str(MSG_DIR.parent),
            str(REPO),
            "--cmake-args",
            f"-DPython3_EXECUTABLE={sys.executable}",
            "-DBUILD_TESTING=OFF",
        ],
        timeout=280,
        AMENT_PREFIX_PATH=str(VENV),
        CMAKE_PREFIX_PATH=str(VENV),
    )

    check = (
        "import prsm_health, prsm_health_msgs.msg;"
        "from rclpy.serialization import serialize_message;"
        "serialize_message(prsm_health_msgs.msg.MotorState());"
        "print(prsm_health.__file__); print(prsm_health_msgs.msg.__file__);"
        "from prsm_health.estimation.params import bundled_params_file;"
        "print(bundled_params_file())"
    )
    # Not from the repo root: `python -c` puts the working directory first on sys.path.
    out = run(
        ["bash", "-c", f"source {install}/setup.bash && python -c '{check}'"],
        timeout=60,
        cwd=tmp_path,
    )
    files = [Path(line) for line in out.splitlines()]
    assert files[0].is_relative_to(install / "prsm_health")
    assert files[1].is_relative_to(install / "prsm_health_msgs")

    share = install / "prsm_health" / "share"
    assert (share / "ament_index/resource_index/packages/prsm_health").is_file()
    assert (share / "prsm_health/package.xml").is_file()
    assert (install / "prsm_health/lib/prsm_health/prsm-health").is_file()
    assert (install / "prsm_health/lib/prsm_health/prsm-health-node").is_file()
    assert (share / "prsm_health/launch/prsm_health.launch.py").is_file()
    assert files[2] == share / "prsm_health/config/default.yaml"  # found via the ament index
    shipped = {p.name for p in files[0].parent.rglob("*.yaml")}
    sources = {p.name for p in (REPO / "prsm_health").rglob("*.yaml")}
    assert shipped == sources
