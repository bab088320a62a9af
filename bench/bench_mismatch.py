"""The estimator with actuator parameters that are wrong by realistic amounts (a benchmark, not
a test).

The simulator runs the scenes with their actuator; the estimator gets the same actuator with
one parameter changed: the motor's torque constant, the gearbox efficiency, the friction
coefficients of paper 002, the lubricant's viscosity or the inertia. Scenes: the benchmark's
sixteen two-jam runs, its eight five-minute one-jam runs and its ten minutes of the nominal
downhole cycle (``benchmark.full_plan``, the plan's seeds), each fed as the replay feeds them
(``benchmark.chunked``), scored against the truth (``benchmark.scored``). Prints one Markdown
row per variant: load RMSE while moving (root mean square over the runs, largest, the nominal
run's), jams identified within a cycle, false declarations, how many runs' load NEES is
consistent and the nominal run's mean NEES, with ``noise.torque_scale_error_rel`` as given
(docs/estimation.md, "When the parameters are wrong").

    .venv/bin/python bench/bench_mismatch.py [--torque-scale-error 0.05] [--variants NAME ...]
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from collections.abc import Callable

import numpy as np

from prsm_health.actuator import Actuator
from prsm_health.benchmark import chunked, cycle_period_s, full_plan, params_for, scored
from prsm_health.estimation.params import Fidelity
from prsm_health.scenes.scene import Scene
from prsm_health.scenes.simulator import simulate

NOMINAL = "nominal-10min"


def _drive(actuator: Actuator, name: str, change: Callable[[float], float]) -> Actuator:
    """``actuator`` with the drive-train field ``name`` changed by ``change``."""
    drive = actuator.drive_train
    changed = dataclasses.replace(drive, **{name: change(getattr(drive, name))})
    return dataclasses.replace(actuator, drive_train=changed)


def _friction(actuator: Actuator, name: str, factor: float) -> Actuator:
    """``actuator`` with the preset's friction field ``name`` multiplied by ``factor``."""
    preset = actuator.preset
    friction = dataclasses.replace(
        preset.friction, **{name: getattr(preset.friction, name) * factor}
    )
    return dataclasses.replace(actuator, preset=dataclasses.replace(preset, friction=friction))


def _inertia(actuator: Actuator, factor: float) -> Actuator:
    """``actuator`` with the motor's and the screw's inertia multiplied by ``factor``."""
    scaled = _drive(actuator, "motor_inertia_kg_m2", lambda j: j * factor)
    return _drive(scaled, "screw_inertia_kg_m2", lambda j: j * factor)


VARIANTS: dict[str, Callable[[Actuator], Actuator]] = {
    "exact": lambda a: a,
    "torque constant +5 %": lambda a: _drive(a, "torque_constant_nm_per_a", lambda k: k * 1.05),
    "torque constant -5 %": lambda a: _drive(a, "torque_constant_nm_per_a", lambda k: k * 0.95),
    "gear efficiency -0.02": lambda a: _drive(a, "gear_efficiency", lambda e: e - 0.02),
    "gear efficiency +0.02": lambda a: _drive(a, "gear_efficiency", lambda e: e + 0.02),
    "sliding friction x1.3": lambda a: _friction(a, "sliding_friction_coefficient", 1.3),
    "sliding friction x0.7": lambda a: _friction(a, "sliding_friction_coefficient", 0.7),
    "hysteresis loss x1.5": lambda a: _friction(a, "hysteresis_loss_coefficient", 1.5),
    "lubricant viscosity x3": lambda a: _friction(a, "lubricant_viscosity_pa_s", 3.0),
    "lubricant viscosity /3": lambda a: _friction(a, "lubricant_viscosity_pa_s", 1.0 / 3.0),
    "inertia x1.5": lambda a: _inertia(a, 1.5),
}


def scenes() -> list[tuple[str, Scene]]:
    """The benchmark's two-jam and one-jam runs and its ten minutes of nominal cycles."""
    return [
        (s.name, s.scene)
        for s in full_plan().scenes
        if s.group in ("two-jam", "one-jam") or s.name == NOMINAL
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--torque-scale-error", type=float, default=0.0)
    parser.add_argument("--variants", nargs="+", choices=list(VARIANTS), default=list(VARIANTS))
    args = parser.parse_args()
    runs = [(name, scene, simulate(scene)) for name, scene in scenes()]
    print(
        "| estimator's parameter | RMSE % (rms, largest, nominal) | jams in 1 cycle | "
        "false declarations | NEES consistent | nominal NEES | s |"
    )
    print("|---|---|---|---|---|---|---|")
    for variant in args.variants:
        begin = time.perf_counter()
        rmse, found, onsets, false, false_s, consistent = [], 0, 0, 0, 0.0, 0
        nominal = nominal_nees = float("nan")
        for name, scene, result in runs:
            params = params_for(scene, Fidelity())
            params = dataclasses.replace(
                params,
                actuator=VARIANTS[variant](params.actuator),
                noise=dataclasses.replace(
                    params.noise, torque_scale_error_rel=args.torque_scale_error
                ),
            )
            states, _ = chunked(params, result.motor)
            metrics = scored(states, result.truth, params)
            cycle = cycle_period_s(scene) or float("inf")
            rmse.append(metrics.load_rmse_percent_rated)
            found += sum(j.delay_s is not None and j.delay_s <= cycle for j in metrics.jams)
            onsets += len(metrics.jams)
            false += metrics.false_jam_declarations
            false_s += metrics.false_jam_seconds
            consistent += metrics.load_nees_consistent is True
            if name == NOMINAL:
                nominal = metrics.load_rmse_percent_rated
                nominal_nees = metrics.load_nees_mean
        values = np.asarray(rmse)
        print(
            f"| {variant} | {np.sqrt(np.mean(values**2)):.2f}, {values.max():.2f}, "
            f"{nominal:.2f} | {found}/{onsets} | {false} ({false_s:.1f} s) | "
            f"{consistent}/{len(runs)} | {nominal_nees:.2f} | {time.perf_counter() - begin:.0f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
