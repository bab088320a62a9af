"""Bag speeds on this machine: writing, the rosbags decode baseline, and this package's reader.

Run ``.venv/bin/python -m prsm_health.bags.speed [--samples N] [--repeats R]``; it writes a
bag of N MotorState messages (1 kHz, ADC-quantised current and speed) to a temporary folder
and prints the best of R runs of each step. The numbers in docs/bags.md come from it.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections.abc import Callable, Sequence
from contextlib import closing
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from prsm_health.bags.baseline import decode_time_baseline
from prsm_health.bags.codecs import decode_motor_states
from prsm_health.bags.mcap_scan import BagScanner
from prsm_health.bags.reader import read_motor_samples
from prsm_health.bags.typestore import typestore
from prsm_health.bags.writer import BagWriter, write_motor_states
from prsm_health.signals import MotorSamples


@dataclass(frozen=True)
class Speeds:
    """Best-of-``repeats`` seconds of each step for ``samples`` messages; bag size in bytes."""

    samples: int
    bag_bytes: int
    write_s: float
    rosbags_decode_s: float
    read_s: float
    decode_only_s: float

    def lines(self) -> list[str]:
        """A small table, one step per line, with microseconds per message."""
        n = self.samples
        rows = [
            ("write (BagWriter + write_motor_states)", self.write_s),
            ("rosbags read + deserialize_cdr (baseline)", self.rosbags_decode_s),
            ("read_motor_samples (scan + fast decode)", self.read_s),
            ("  of which fast CDR decode only", self.decode_only_s),
        ]
        head = f"{n} MotorState messages, bag {self.bag_bytes / n:.1f} bytes/message"
        body = [f"{name:44s} {s * 1e3:8.1f} ms  {s / n * 1e6:6.2f} us/msg" for name, s in rows]
        return [head, *body, f"baseline / read = {self.rosbags_decode_s / self.read_s:.1f}"]


def sample_run(samples: int) -> MotorSamples:
    """A plausible motor record: 1 kHz, 1 mA current and 0.01 rad/s speed resolution."""
    rng = np.random.default_rng(0)
    t = 1e-3 * np.arange(samples, dtype=np.float64)
    current = np.round(3.0 * np.sin(np.pi * t) + 0.05 * rng.normal(size=samples), 3)
    speed = np.round(100.0 + 5.0 * np.sin(0.2 * np.pi * t) + 0.1 * rng.normal(size=samples), 2)
    return MotorSamples(1.7e9 + t, current, speed, np.cumsum(speed) * 1e-3)


def _best(step: Callable[[], object], repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        step()
        times.append(time.perf_counter() - start)
    return min(times)


def measure(samples: int, repeats: int, folder: Path) -> Speeds:
    """Time each step ``repeats`` times on a bag of ``samples`` messages written in ``folder``."""
    motor = sample_run(samples)
    typestore()
    bags = iter(range(repeats))

    def write() -> None:
        with BagWriter(folder / f"bag{next(bags)}") as writer:
            write_motor_states(writer, motor)

    write_s = _best(write, repeats)
    bag = folder / "bag0"
    with closing(BagScanner([bag / "bag0.mcap"])) as scanner:
        batches = list(scanner.batches("/motor_state"))

    def decode_only() -> None:
        for batch in batches:
            decode_motor_states(batch.buffer, batch.starts, batch.sizes)

    return Speeds(
        samples=samples,
        bag_bytes=sum(f.stat().st_size for f in bag.iterdir()),
        write_s=write_s,
        rosbags_decode_s=min(decode_time_baseline(bag) for _ in range(repeats)),
        read_s=_best(lambda: read_motor_samples(bag), repeats),
        decode_only_s=_best(decode_only, repeats),
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Command line entry: print the table of :meth:`Speeds.lines`."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--samples", type=int, default=60_000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    for option, value in (("--samples", args.samples), ("--repeats", args.repeats)):
        if value < 1:
            parser.error(f"{option} must be at least 1, got {value}")
    with tempfile.TemporaryDirectory() as folder:
        speeds = measure(args.samples, args.repeats, Path(folder))
    print("\n".join(speeds.lines()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
