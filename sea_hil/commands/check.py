"""`sea-hil check --config FILE [--trajectory CSV]`: the input checks a session makes at load (sea_hil/input_check.py),
every problem on its own line, without running anything. Exit 0 when the inputs pass, 2 when one does not."""
from __future__ import annotations

import argparse
import sys

from sea_hil.commands.common import add_link_args, add_period_arg, add_scenario_args, add_scheme_args, config_from_args
from sea_hil.input_check import problems


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("check", help="check a config (and trajectory) against the drive's limits without running",
                       description="Load the config as `sea-hil run` would and print the verdict of the input "
                                   "checks: start pose inside the drive's soft position limits and the end stops; "
                                   "the trajectory and its lead-in inside the soft position and velocity limits, "
                                   "the end stops and the setpoint envelope; CSV times; link traces and periods. "
                                   "One line per problem; exit 2 if there is any.")
    p.add_argument("--config", metavar="FILE", help="TOML file overlaid on the embedded defaults")
    p.add_argument("--trajectory", metavar="CSV", help="desired trajectory CSV with columns t, theta1, theta2 (rad)")
    add_link_args(p)
    add_period_arg(p)
    add_scheme_args(p)
    add_scenario_args(p)
    p.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:

    cfg = config_from_args(args)   # loaded unchecked: every problem is printed below, not only the first
    found = problems(cfg)
    what = args.config or "the embedded defaults"
    if args.trajectory:
        what += f" with trajectory {args.trajectory}"
    for p in found:   # one line per problem, as `run` would print the first
        print(f"sea-hil check: error: {p.message}", file=sys.stderr)
    if found:
        return 2
    print(f"sea-hil check: {what}: ok")
    return 0
