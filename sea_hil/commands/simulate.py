"""`sea-hil simulate`: offline closed loop (no network)."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from sea_hil.commands.common import add_config_args, add_period_arg, add_scenario_args, add_strict_arg, config_from_args
from sea_hil.errors import ConfigError
from sea_hil.offline.simulate import run_compare, run_simulation
from sea_hil.report.console import files_in, print_end_of_run
from sea_hil.verdict.rules import strict_status


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("simulate", help="offline closed-loop simulation (no network); paper Fig. 2-4",
                       description="Run the plant model with TT or ET SMC in one process and write "
                                   "DIR/summary.json plus figures. No link: the paper's scheme (trigger at the "
                                   "controller, a state every sample), whatever trigger.placement says; the default "
                                   "scheme offline: `sea-hil run --lockstep` or `sea-hil sweep`.")
    p.add_argument("--controller", choices=("tt", "et"), default="et", help="time- or event-triggered SMC")
    p.add_argument("--compare", action="store_true", help="run both and write DIR/compare.md (TT vs ET vs paper)")
    p.add_argument("--trajectory", metavar="CSV", help="desired trajectory CSV with columns t, theta1, theta2 (rad)")
    p.add_argument("--cycles", type=int, help="walking cycles to simulate (default from config: 1)")
    p.add_argument("--quantise", action="store_true",
                   help="round measurements and voltages to their CAN frame resolutions (docs/can-protocol.md)")
    p.add_argument("--out", required=True, type=Path, metavar="DIR", help="output directory")
    p.add_argument("--json", action="store_true", help="print summary.json instead of the end-of-run table")
    add_config_args(p)
    add_strict_arg(p)
    add_period_arg(p)
    add_scenario_args(p)
    p.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    if args.cycles is not None and args.cycles < 1:
        raise ConfigError("--cycles must be >= 1")
    cfg = config_from_args(args, check="offline")
    if args.compare:
        tt, et, table = run_compare(cfg, args.out, args.cycles, quantise=args.quantise)
        print(table)
        return max(strict_status(tt), strict_status(et)) if args.strict else 0
    else:
        summary = run_simulation(cfg, args.controller, args.out, args.cycles, quantise=args.quantise)
        if args.json:
            print(json.dumps(summary, indent=2, sort_keys=True))
        else:
                print_end_of_run(summary, files_in(args.out), command="simulate",
                             tt_msgs=round(summary["duration_s"] / cfg.controller.sample_period_s))
    return strict_status(summary) if args.strict else 0
