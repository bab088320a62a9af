"""Speed of the truth simulator on this machine (a benchmark, not a test).

Simulates the bundled ``nominal-downhole`` scene (60 s at 1 kHz, radial load, both loading
cases) in table mode, first with the roller tables still to build (a fresh process's cost),
then again with them built; and the first ``--exact-seconds`` of it in exact mode (the physics
core at every sample; the first 2 s are a support step at standstill without load, the rest is
the first stroke). Prints wall times and the multiple of real time.
Issue floor: table mode >= 20x real time.

    .venv/bin/python bench/bench_simulator.py [--exact-seconds S]
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from collections.abc import Callable

from prsm_health.scenes.scene import load_scene
from prsm_health.scenes.simulator import simulate


def timed(label: str, simulated_s: float, run: Callable[[], object]) -> None:
    """Print the wall time of ``run()`` and the real-time factor."""
    start = time.perf_counter()
    run()
    wall = time.perf_counter() - start
    print(f"{label:44s} {wall:8.2f} s  {simulated_s / wall:8.1f}x real time")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--exact-seconds", type=float, default=5.0)
    exact_s = parser.parse_args().exact_seconds
    scene = load_scene("nominal-downhole")
    duration = scene.duration_s
    print(f"scene {scene.name}: {duration:g} s at {scene.rate_hz:g} Hz")
    timed("table mode, tables built on the way", duration, lambda: simulate(scene))
    timed("table mode, tables built", duration, lambda: simulate(scene))
    short = dataclasses.replace(scene, duration_s=exact_s)
    timed(
        f"exact mode, first {exact_s:g} s",
        exact_s,
        lambda: simulate(short, exact=True),
    )


if __name__ == "__main__":
    main()
