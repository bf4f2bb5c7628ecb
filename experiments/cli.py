"""`rbp experiment NAME [options]`: run one of the paper's experiments (experiments/NAME.py).

The experiment's own options follow its name (`rbp experiment NAME --help` lists them); the
module is imported only when it runs, so `rbp --help` stays instant.
"""

from __future__ import annotations

import argparse
import importlib
from typing import Any

EXPERIMENTS = {
    "baseline_comparison": "RBP against the naive planner over random caves (Fig. 4)",
    "timing_table": "computation time of each planning stage (Table I)",
    "snapshots": "snapshots of a climb through one cave (Fig. 5)",
    "seed_vs_scp": "what SCP makes of the seeds, per phase and over trials (Fig. 6)",
    "rig_experiment": "a body movement on the (simulated) rig over LCM (Fig. 7)",
    "monte_carlo": "predicted p_path against simulated success rates (calibration)",
    "calibration": "p_path against 2000 simulated climbs on a fixed set of caves (issue 17)",
    "param_sweep": "success rate and p_path against one parameter",
}


def add_experiment_command(subparsers: Any) -> argparse.ArgumentParser:
    """Register `experiment` on the `rbp` sub-command parsers."""
    listing = "\n".join(f"  {name:20s} {text}" for name, text in EXPERIMENTS.items())
    p = subparsers.add_parser(
        "experiment", help="run one of the paper's experiments (rbp experiment NAME --help)",
        description=f"{__doc__.splitlines()[0]}\n\nexperiments:\n{listing}\n\n"
                    "Sweeps share --out DIR, --trials N, --workers W and --cluster "
                    "tcp://HOST:PORT; finished trials in DIR/trials/ are kept and skipped.",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("name", choices=tuple(EXPERIMENTS), metavar="NAME",
                   help="the experiment: " + ", ".join(EXPERIMENTS))
    p.add_argument("options", nargs=argparse.REMAINDER,
                   help="the experiment's options (see rbp experiment NAME --help)")
    p.set_defaults(func=cmd_experiment)
    return p


def cmd_experiment(args: argparse.Namespace) -> int:
    """Run experiments.NAME.main with the options that follow NAME."""
    module = importlib.import_module(f"experiments.{args.name}")
    return int(module.main(list(args.options), prog=f"rbp experiment {args.name}") or 0)
