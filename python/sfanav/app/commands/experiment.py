"""``sfanav demo`` and ``sfanav experiment``: the whole pipeline on the demo garden, and the thesis's experiments."""

from __future__ import annotations

import argparse

from .. import arguments as arg
from ..common import log, wrap
from ..failures import UsageError
from ..registry import command


@command("demo")
def _add_demo(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    from ..demo import DEMO_NETWORK

    p = sub.add_parser(
        "demo",
        help="simulate a garden, train without ground truth, localize a test run and report (about 2 minutes)",
        description=wrap("The whole pipeline on the built-in simulator, as a robot has it (images and wheel "
                    "odometry, no ground truth): generates the 'demo' garden (8x8 m, a grid exploration run "
                    f"and a test walk), trains the {DEMO_NETWORK} network under simulated rotation, learns the "
                    "exploration run's positions from its images and odometry (pose graph), fits the readout "
                    "to them, localizes the test walk from single images and fused with its odometry (EKF), "
                    "and prints MAE, MED and eta beside the thesis's section 5.1.1 figures, the two "
                    "baselines, the same network with its readout on ground truth and the thesis's "
                    "configuration. Writes the dataset, the models, the estimates (CSV), plots and a "
                    "Markdown report under --out. Ground truth is used only to evaluate and for the "
                    "reference rows."),
        epilog="outputs: DIR/dataset, DIR/model.sfa (no ground truth), DIR/model-ground-truth.sfa, "
               "DIR/test-estimates.csv, DIR/report.md, DIR/*.png, DIR/demo.json",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--out", default="sfanav-demo", metavar="DIR", help="output directory (default sfanav-demo)")
    p.add_argument("--seed", type=arg.nonneg_int, default=0, help="seed of the garden and the runs (default 0)")
    p.add_argument("--overwrite", action="store_true", help="replace the outputs of an earlier demo in --out")
    p.add_argument("--quick", action="store_true",
                   help="a seconds-long smoke run (tiny images, few frames, a small network); not meaningful")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(run=_run_demo)
    return p


def _run_demo(args: argparse.Namespace) -> int:
    from ..demo import run_demo

    result = run_demo(args.out, seed=args.seed, overwrite=args.overwrite, quick=args.quick,
                      progress=not args.no_progress, log=log)
    print(result.table())
    if result.notes:
        print()
        print(result.notes)
    return 0


@command("experiment")
def _add_experiment(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    from ... import experiments

    p = sub.add_parser(
        "experiment",
        help="rerun one of the thesis's experiments on the simulator (--list lists them)",
        description=wrap("Rerun one of the thesis's experiments on the built-in simulator: simulates the scene, "
                    "trains, evaluates, prints a table of each metric with the thesis's value beside "
                    "sfanav's, and writes the same as JSON ({\"experiment\": NAME, \"rows\": [{\"metric\", "
                    "\"thesis\", \"sfanav\"}, ...]}) plus plots under --out. Localization experiments also "
                    "run the perfect-memory and Fourier-signature baselines on the same images."),
        epilog="experiments:\n" + "\n".join(f"  {n:<8} {experiments.get(n).title}" for n in experiments.names())
               + "\n\nexample:\n  sfanav experiment --list\n  sfanav experiment 5.1.1 --out results",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("name", nargs="?", metavar="NAME", help="experiment name (see --list)")
    p.add_argument("--list", action="store_true", help="list the experiments and exit")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="output directory (default sfanav-results/NAME); writes NAME.json and plots")
    p.add_argument("--quick", action="store_true",
                   help="a seconds-long smoke run (tiny images and grids, few frames); numbers not meaningful")
    p.add_argument("--seed", type=arg.nonneg_int, default=0, help="seed of scenes and runs (default 0)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(run=_run_experiment)
    return p


def _run_experiment(args: argparse.Namespace) -> int:
    import time
    from pathlib import Path

    from ... import experiments

    if args.list:
        if args.name:
            raise UsageError("give either NAME or --list")
        names = experiments.names()
        width = max((len(n) for n in names), default=0)
        for n in names:
            print(f"{n:<{width}}  {experiments.get(n).title}")
        return 0
    if not args.name:
        raise UsageError("give an experiment NAME (sfanav experiment --list shows them)")
    exp = experiments.get(args.name)  # ValueError with the known names
    out = Path(args.out) if args.out else Path("sfanav-results") / args.name
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out} is a file")
    log(f"experiment {exp.name}: {exp.title}" + (" (quick smoke run)" if args.quick else ""))
    t0 = time.perf_counter()
    result = experiments.run(exp.name, out, quick=args.quick, seed=args.seed, progress=not args.no_progress)
    print(result.table())
    if result.notes:
        print()
        print(result.notes)
    print(f"\nwrote {out / (exp.name + '.json')} and {len(result.plots)} plots in {time.perf_counter() - t0:.0f} s")
    return 0
