"""``prsm-health demo`` (``make demo``): the node, a scene bag played into it, the monitor.

Everything on loopback (:func:`~prsm_health.ros.runtime.loopback_env`; the domain id is
``ROS_DOMAIN_ID`` if set, else :data:`DEMO_DOMAIN_ID`), with a hard time limit. The node runs
in its own process with a fresh state file in the work directory (its log next to it), the
player in another; this process shows the monitor's table while the bag plays, then prints a
summary of the last estimate (load, jam count and probabilities, precision loss) beside the
bag's ground truth, and the first diagnostics the node publishes after the bag's end: they
count every sample, and come before the node's stale timeout (1 s; they are published at
:data:`DIAGNOSTICS_RATE_HZ`), after which they would all be STALE.

The node's estimator parameters are the bundled config/default.yaml with the ``actuator``
section of the scene the bag was simulated from, when it says
(:func:`~prsm_health.scenes.recording.bag_actuator`): the scenes accelerate wear
(``wear_acceleration``) so that a minute shows a measurable precision loss, and the estimator
must know by how much.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from threading import Event
from typing import IO, Any, NamedTuple

import numpy as np
import yaml
from rosbags.rosbag2 import Reader, ReaderError

from prsm_health.bags.errors import BagError
from prsm_health.bags.reader import read_truth
from prsm_health.estimation.params import bundled_params_file
from prsm_health.node_params import params_with_actuator
from prsm_health.ros.monitor import Monitor, MonitorOptions
from prsm_health.ros.runtime import loopback_env, ros_session
from prsm_health.scenes.recording import usable_bag_actuator

DEMO_DOMAIN_ID = 42
#: What the demo plays of the bag (the node's default input).
INPUT_TOPIC = "/motor_state"
#: The node's diagnostics rate in the demo [Hz] (the table refreshes at this rate): faster than
#: one per stale_timeout_s, so that the first after the bag's end is not yet STALE.
DIAGNOSTICS_RATE_HZ = 2.0
#: After the player ends, wait until no estimate came for this long [s].
QUIET_S = 1.0
#: The longest wait for the node's next diagnostics after the bag [s]: six of their periods.
NEXT_DIAGNOSTICS_S = 6.0 / DIAGNOSTICS_RATE_HZ
STOP_TIMEOUT_S = 10.0


class DemoError(RuntimeError):
    """The demo could not run (no bag, the node did not come up, time limit)."""


def bag_duration_s(bag: Path) -> float:
    """The bag's duration (last minus first log time) [s]."""
    try:
        with Reader(bag) as reader:
            return float(reader.duration) / 1e9
    except (ReaderError, OSError) as exc:
        raise DemoError(
            f"cannot open the bag {bag} ({exc}); the demo plays intact bags (the scene bags are "
            "made by prsm-health simulate); prsm-health replay and play read a damaged one up "
            "to its damage"
        ) from exc


def demo_params(bag: Path, workdir: Path) -> tuple[Path, str]:
    """The node's params file for ``bag`` (module docstring) and a line saying what it is."""
    scene = usable_bag_actuator(bag, bundled_params_file())
    if scene is None:
        return bundled_params_file(), f"params {bundled_params_file()}"
    params = params_with_actuator(bundled_params_file(), scene)
    path = workdir / "params.yaml"
    path.write_text(yaml.safe_dump(params, sort_keys=False))
    acceleration = scene.actuator.wear_acceleration
    return path, f"params {path}: the actuator of {scene.origin}, wear x {acceleration:g}"


class TruthPoint(NamedTuple):
    """The ground truth at one time: |axial load| [N], jammed rollers, precision loss [um]."""

    axial_load_n: float
    jammed_rollers: int
    precision_loss_um: float


def truth_at(bag: Path, stamp_s: float) -> TruthPoint | None:
    """The bag's ground truth at ``stamp_s`` (None if the bag has none)."""
    try:
        truth = read_truth(bag)
    except BagError:
        return None
    if truth is None or len(truth) == 0:
        return None
    i = min(int(np.searchsorted(truth.stamp_s, stamp_s)), len(truth) - 1)
    return TruthPoint(
        abs(float(truth.axial_load_n[i])),
        int(truth.jammed_rollers[i]),
        float(truth.precision_loss_m[i]) * 1e6,
    )


def _stop(process: subprocess.Popen[bytes] | None) -> None:
    """SIGINT (the node saves its state), then SIGKILL if it does not end."""
    if process is None or process.poll() is not None:
        return
    process.send_signal(signal.SIGINT)
    try:
        process.wait(STOP_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()


def _spin_while_alive(
    monitor: Monitor,
    node: subprocess.Popen[bytes],
    log: IO[bytes],
    done: Callable[[], bool],
    deadline: float,
    what: str,
    stop: Event,
) -> None:
    """:func:`_spin_until` ``done()`` or the node's end; DemoError if the node ended."""
    _spin_until(monitor, lambda: done() or node.poll() is not None, deadline, what, stop)
    if node.poll() is not None:
        raise DemoError(f"the node ended with code {node.returncode}; see {log.name}")


def _spin_until(
    monitor: Monitor, done: Callable[[], bool], deadline: float, what: str, stop: Event
) -> None:
    """Receive until ``done()``; DemoError at the deadline or on SIGINT/SIGTERM."""
    while not done():
        if stop.is_set():
            raise DemoError(f"interrupted while waiting for {what}")
        if time.monotonic() > deadline:
            raise DemoError(f"time limit reached while waiting for {what}")
        monitor.spin_once()


def summary(
    health: dict[str, Any] | None,
    diagnostics: dict[str, Any] | None,
    truth: TruthPoint | None = None,
) -> str:
    """The closing summary of the last estimate, the truth at its time, and the diagnostics
    (with the time of the estimate they report: the last ones before the node went silent,
    which may be an estimate or two before the last)."""
    if health is None:
        return "summary: no estimate was received"
    probabilities = health["jammed_rollers_probability"]
    shown = ", ".join(f"p({k}) = {p:.3f}" for k, p in enumerate(probabilities) if p >= 0.001)
    lines = [
        f"summary at bag time {health['stamp']:.2f} s"
        f" ({health['samples_accepted']} samples accepted,"
        f" {health['samples_rejected']} rejected):",
        f"  axial load      {health['axial_load_n'] / 1e3:.2f} kN"
        f" ± {health['axial_load_std_n'] / 1e3:.2f} kN",
        f"  jammed rollers  {health['jammed_rollers_most_likely']} most likely ({shown})",
        f"  precision loss  {health['precision_loss_um']:.4g} um"
        f" ± {health['precision_loss_std_um']:.2g} um"
        f" (rate {health['precision_loss_rate_um_per_h']:.3g} um/h)",
    ]
    if truth is not None:
        lines.append(
            f"  truth           {truth.axial_load_n / 1e3:.2f} kN, {truth.jammed_rollers} jammed,"
            f" {truth.precision_loss_um:.4g} um lost"
        )
    statuses = diagnostics["status"] if diagnostics else []
    stamps = {
        s["values"]["estimate_stamp_s"] for s in statuses if "estimate_stamp_s" in s["values"]
    }
    if stamps:  # the last diagnostics before the bag's end: an earlier estimate, said
        lines.append(f"diagnostics of the estimate at bag time {', '.join(sorted(stamps))} s:")
    for status in statuses:
        lines.append(f"  {status['level']:<5} {status['name']}: {status['message']}")
    return "\n".join(lines)


def run_demo(bag: Path, *, rate: float, timeout_s: float, workdir: Path) -> int:
    """Run the demo (module docstring); 0 if the node produced estimates."""
    duration = bag_duration_s(bag)
    os.environ.update(loopback_env(os.environ, DEMO_DOMAIN_ID))
    workdir.mkdir(parents=True, exist_ok=True)
    state_file = workdir / "state.json"
    state_file.unlink(missing_ok=True)
    deadline = time.monotonic() + timeout_s
    params_file, params_line = demo_params(bag, workdir)
    print(
        f"demo: {bag} ({duration:.1f} s at rate {rate:g}), ROS_DOMAIN_ID"
        f" {os.environ['ROS_DOMAIN_ID']}, loopback only; node log: {workdir / 'node.log'};"
        f" {params_line}",
        flush=True,
    )
    node: subprocess.Popen[bytes] | None = None
    player: subprocess.Popen[bytes] | None = None
    verdicts: dict[str, Any] | None = None
    log: IO[bytes]
    with (workdir / "node.log").open("wb") as log, ros_session() as stop:
        monitor = Monitor(MonitorOptions())
        try:
            node_command = [sys.executable, "-m", "prsm_health.ros.node", "--ros-args"]
            node_command += ["-p", f"state_file:={state_file}", "-p", "hardware_id:=demo"]
            node_command += ["-p", f"diagnostics_rate_hz:={DIAGNOSTICS_RATE_HZ}"]
            node_command += ["-p", f"params_file:={params_file}"]
            node = subprocess.Popen(node_command, stdout=log, stderr=subprocess.STDOUT)  # noqa: S603
            _spin_while_alive(
                monitor,
                node,
                log,
                lambda: monitor.latest_diagnostics is not None,
                deadline,
                "the node",
                stop,
            )
            play_command = [sys.executable, "-m", "prsm_health", "play", str(bag)]
            play_command += ["--topics", INPUT_TOPIC, "--rate", f"{rate:g}"]
            play_command += ["--wait-for-subscribers", "20"]
            player = subprocess.Popen(play_command)  # noqa: S603
            _spin_until(
                monitor,
                lambda: player.poll() is not None,
                deadline,
                "the end of the bag",
                stop,
            )
            at_end = monitor.latest_diagnostics
            _spin_while_alive(
                monitor,
                node,
                log,
                lambda: monitor.latest_diagnostics is not at_end,
                min(deadline, time.monotonic() + NEXT_DIAGNOSTICS_S),
                "the node's diagnostics after the bag",
                stop,
            )
            verdicts = monitor.latest_diagnostics  # every sample counted, not yet STALE
            count, changed = monitor.health_received, time.monotonic()
            while time.monotonic() - changed < QUIET_S and not stop.is_set():
                if time.monotonic() > deadline:
                    raise DemoError("time limit reached while waiting for the last estimates")
                monitor.spin_once()
                if monitor.health_received != count:
                    count, changed = monitor.health_received, time.monotonic()
        finally:
            _stop(player)
            _stop(node)
            monitor.close()
        last = monitor.latest_health
        truth = truth_at(bag, last["stamp"]) if last is not None else None
        print(summary(last, verdicts, truth), flush=True)
    return 0 if monitor.latest_health is not None else 1
