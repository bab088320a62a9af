"""``prsm-health bench``: the estimator benchmark (run time against error).

``prsm-health bench [--quick] [--out DIR] [--scenes ...] [--configs ...] [--held-out SEED]
[--params YAML]`` runs :func:`~prsm_health.benchmark.run_benchmark` on the full plan (about
half an hour on 2 cores; with ``--held-out``, its generated runs drawn from other seeds) or the
CI-sized ``--quick`` one and writes ``results.json``, ``results.md`` and ``pareto.png`` into
``--out`` (default ``build/bench``); ``--scenes`` and ``--configs`` restrict the plan, and the
files' titles name the restriction. ``--params`` benchmarks other estimator parameters than
the bundled ``config/default.yaml`` (each scene's actuator still comes from the scene). The
floors are printed (measured, pass/fail); the exit code does not depend on them.
docs/performance.md explains the plan and the latest run.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import sys
from pathlib import Path
from typing import Any

from prsm_health.benchmark import (
    CONFIGURATION_NAMES,
    GROUPS,
    base_params,
    full_plan,
    quick_plan,
    run_benchmark,
    select,
)
from prsm_health.benchmark_report import FILES, write_results
from prsm_health.output_paths import make_folder, remove_made_folders
from prsm_health.physics.errors import ParameterError
from prsm_health.scenes.scene import BUNDLED_BAGS


def add_bench_command(commands: Any) -> None:
    """Register ``bench`` on the CLI's subparsers."""
    parser = commands.add_parser("bench", help="benchmark the estimator: run time against error")
    parser.add_argument("--quick", action="store_true", help="CI-sized run (under 2 minutes)")
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("build/bench"),
        metavar="DIR",
        help=f"folder for {', '.join(FILES)} (made if needed; default build/bench)",
    )
    parser.add_argument(
        "--scenes",
        nargs="+",
        metavar="NAME",
        help=f"scenes (the envelope's too) or groups ({', '.join(GROUPS)}) to run; default all",
    )
    parser.add_argument(
        "--configs",
        nargs="+",
        metavar="NAME",
        help=f"configurations to run ({', '.join(CONFIGURATION_NAMES)}); default all",
    )
    parser.add_argument(
        "--held-out",
        type=int,
        metavar="SEED",
        help="draw the generated runs (two-jam, one-jam, wear-prior, long) from other seeds, "
        "derived from SEED: runs no tuning on the default plan has seen (full plan only)",
    )
    parser.add_argument(
        "--params",
        type=Path,
        metavar="YAML",
        help="estimator parameters to benchmark instead of the bundled config/default.yaml "
        "(each scene's actuator still comes from the scene)",
    )
    parser.add_argument(
        "--bags",
        type=Path,
        default=BUNDLED_BAGS,
        metavar="DIR",
        help="the scene bags, each named after its scene as `make bags` writes them "
        "(default: the bundled bags/)",
    )
    parser.set_defaults(handler=run_bench)


def run_bench(args: argparse.Namespace) -> int:
    """Run the planned benchmark, write the files, print the floors."""
    if not logging.getLogger().handlers:
        logging.basicConfig(level=logging.INFO, format="bench: %(message)s", stream=sys.stderr)
    if args.quick and args.held_out is not None:
        raise ValueError("--held-out: only with the full plan, not with --quick")
    plan = quick_plan(args.bags) if args.quick else full_plan(args.bags, held_out=args.held_out)
    missing = [str(s.bag) for s in plan.scenes if s.bag is not None and not s.bag.is_dir()]
    if missing:
        raise ValueError(f"--bags: no bag {', '.join(missing)} (make bags)")
    plan = select(plan, scenes=args.scenes, configs=args.configs)
    restricted = [
        f"{what} {' '.join(names)}"
        for what, names in (("scenes", args.scenes), ("configurations", args.configs))
        if names is not None
    ]
    if restricted:  # the titles of the files say what ran
        plan = dataclasses.replace(plan, mode=f"{plan.mode}, restricted to {'; '.join(restricted)}")
    if args.params is not None:
        try:  # checked before anything runs, and named by the option
            base_params(args.params)
        except ParameterError as exc:
            raise ValueError(f"--params: {exc}") from exc  # the error names the file
        plan = dataclasses.replace(
            plan, params_file=args.params, mode=f"{plan.mode}, parameters {args.params}"
        )
    made = make_folder(args.out, "--out")  # now, not after the run
    try:
        results = run_benchmark(plan)
        floors = write_results(results, args.out)
    finally:
        remove_made_folders(made)  # still empty: the run failed
    print(f"{args.out}: {', '.join(FILES)} ({results.elapsed_s / 60:.1f} min)")
    for floor in floors:
        verdict = {True: "pass", False: "FAIL", None: "-"}[floor.passed]
        print(f"  {verdict:4s}  {floor.name}: {floor.measured}")
    return 0
