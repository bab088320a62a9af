"""The ROS subcommands of ``prsm-health``: play, monitor, demo.

:func:`add_ros_commands` registers them on the CLI's subparsers; each sets ``handler`` to
its runner. rclpy is imported only when one of them runs, so ``prsm-health model`` works
without ROS.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import TypeVar

from prsm_health.interrupt import EXIT_INTERRUPTED
from prsm_health.node_params import accelerated_wear_note
from prsm_health.scenes.scene import BUNDLED_BAGS

Parser = TypeVar("Parser", bound=argparse.ArgumentParser)
#: The scene bag ``make demo`` plays (made by ``prsm-health simulate``, see bags/).
DEMO_BAG = BUNDLED_BAGS / "sudden-jam"


def number_or_nan(text: str) -> float:
    """``text`` as a float, NaN if it is not a number (which the argparse types refuse)."""
    try:
        return float(text)
    except ValueError:
        return math.nan


def _positive(text: str) -> float:
    value = number_or_nan(text)
    if not (math.isfinite(value) and value > 0.0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text!r}")
    return value


def _non_negative(text: str) -> float:
    value = number_or_nan(text)
    if not (math.isfinite(value) and value >= 0.0):
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {text!r}")
    return value


def _count(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = -1  # refused below, with the same message
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be an integer >= 0, got {text!r}")
    return value


def add_ros_commands(commands: argparse._SubParsersAction[Parser]) -> None:
    """Add ``play``, ``monitor`` and ``demo`` to the ``prsm-health`` subparsers."""
    play = commands.add_parser("play", help="publish a bag's messages over DDS with their timing")
    play.add_argument(
        "bag",
        type=Path,
        help="rosbag2 directory (MCAP or SQLite) or .mcap file; a damaged MCAP bag is played "
        "up to the damage",
    )
    play.add_argument("--rate", type=_positive, default=1.0, help="speed factor (default 1)")
    play.add_argument("--clock", action="store_true", help="publish /clock (bag log time)")
    play.add_argument(
        "--clock-rate",
        type=_positive,
        metavar="HZ",
        help="/clock messages per second of bag time, with --clock (default 100)",
    )
    play.add_argument("--topics", nargs="+", default=[], metavar="TOPIC", help="only these")
    play.add_argument("--loop", action="store_true", help="start again at the end")
    play.add_argument(
        "--wait-for-subscribers",
        type=_non_negative,
        default=0.0,
        metavar="S",
        help="wait up to S seconds for a subscriber on every played topic (default: no wait)",
    )
    play.set_defaults(handler=_run_play)

    monitor = commands.add_parser("monitor", help="live table of the node's health/diagnostics")
    monitor.add_argument("--node", default="/prsm_health", help="node name (default /prsm_health)")
    monitor.add_argument("--json", action="store_true", help="one JSON object per message")
    monitor.add_argument(
        "--count",
        type=_count,
        default=0,
        metavar="N",
        help="stop after N records printed: tables, or with --json objects of either topic "
        "(0: no limit)",
    )
    monitor.add_argument(
        "--timeout",
        type=_non_negative,
        default=0.0,
        metavar="S",
        help="stop after S seconds (default 0: wait forever)",
    )
    monitor.add_argument(
        "--hardware-id",
        metavar="ID",
        help="show the statuses of ID (default: the node's hardware_id, asked from the node)",
    )
    monitor.set_defaults(handler=_run_monitor)

    demo = commands.add_parser("demo", help="node + bag + monitor on loopback, then a summary")
    demo.add_argument("--bag", type=Path, default=DEMO_BAG, help=f"default {DEMO_BAG}")
    demo.add_argument("--rate", type=_positive, default=2.0, help="playback speed (default 2)")
    demo.add_argument(
        "--timeout", type=_positive, default=300.0, metavar="S", help="hard limit (default 300)"
    )
    demo.add_argument(
        "--workdir",
        type=Path,
        default=Path("build", "demo"),
        metavar="DIR",
        help="for the node's parameters, state and log (default build/demo)",
    )
    demo.set_defaults(handler=_run_demo)


def _warn_play(text: str) -> None:
    print(f"prsm-health play: warning: {text}", file=sys.stderr)


def _run_play(args: argparse.Namespace) -> int:
    """Play the bag; 1 if the play failed (also: nothing to play), a reliable subscriber
    missed messages, or the bag is damaged (its messages before the damage are played, the
    damage printed at the end); else EXIT_INTERRUPTED if stopped by SIGINT/SIGTERM. A
    ``--clock-rate`` without ``--clock`` is a usage error."""
    from prsm_health.ros.player import (
        DEFAULT_CLOCK_RATE_HZ,
        FINAL_ACK_TIMEOUT_S,
        PlayError,
        PlayInputError,
        PlayOptions,
        counts_text,
        open_bag,
        play,
    )
    from prsm_health.ros.runtime import ros_session

    options = PlayOptions(
        rate=args.rate,
        clock=args.clock,
        clock_rate_hz=DEFAULT_CLOCK_RATE_HZ if args.clock_rate is None else args.clock_rate,
        topics=tuple(args.topics),
        loop=args.loop,
        wait_for_subscribers_s=args.wait_for_subscribers,
    )
    if args.clock_rate is not None and not args.clock:
        raise PlayInputError("--clock-rate sets the rate of --clock's /clock: give --clock too")
    note = accelerated_wear_note(args.bag)
    if note is not None:
        print(note, file=sys.stderr)
    try:
        with ros_session() as stop, open_bag(args.bag, options.topics) as source:
            report = play(source, options, stop, _warn_play)
    except PlayError as exc:
        print(f"prsm-health play: error: {exc}", file=sys.stderr)
        return 1
    topics = counts_text(report.published)
    state = "interrupted" if report.interrupted else "done"
    print(
        f"play {state}: {topics or 'nothing'} published in {report.passes} pass(es);"
        f" largest lateness {report.max_late_s * 1e3:.1f} ms"
    )
    if report.unacknowledged:
        print(
            f"prsm-health play: error: not acknowledged by every reliable subscriber within"
            f" {FINAL_ACK_TIMEOUT_S:g} s, or one left: {', '.join(report.unacknowledged)}"
            " (messages may be lost)",
            file=sys.stderr,
        )
    damaged = report.damage is not None and not report.interrupted  # stopped before it
    if damaged:
        print(f"prsm-health play: error: played up to the damage: {report.damage}", file=sys.stderr)
    if report.unacknowledged or damaged:
        return 1
    return EXIT_INTERRUPTED if report.interrupted else 0


def _run_monitor(args: argparse.Namespace) -> int:
    """Show the node's health; 1 if it ended without what was asked (``--count`` records,
    or, without it, anything), saying what is missing; EXIT_INTERRUPTED if stopped by
    SIGINT/SIGTERM (the shortfall is still printed)."""
    from prsm_health.ros.monitor import Monitor, MonitorOptions
    from prsm_health.ros.runtime import ros_session

    options = MonitorOptions(
        node=args.node,
        json=args.json,
        count=args.count,
        timeout_s=args.timeout,
        hardware_id=args.hardware_id,
    )
    with ros_session() as stop:
        monitor = Monitor(options)
        try:
            complete = monitor.run(stop)
        finally:
            monitor.close()
    if not complete:
        print(f"prsm-health monitor: {monitor.shortfall()}", file=sys.stderr)
    if stop.is_set():
        return EXIT_INTERRUPTED
    return 0 if complete else 1


def _run_demo(args: argparse.Namespace) -> int:
    from prsm_health.ros.demo import DemoError, run_demo
    from prsm_health.ros.player import PlayOptions

    PlayOptions(rate=args.rate)  # the demo's player's rate: refused here, as play refuses it
    if not args.bag.exists():
        raise ValueError(f"--bag: {args.bag} does not exist")
    try:
        return run_demo(args.bag, rate=args.rate, timeout_s=args.timeout, workdir=args.workdir)
    except DemoError as exc:
        print(f"prsm-health demo: error: {exc}", file=sys.stderr)
        return 1
