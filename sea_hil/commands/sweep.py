"""`sea-hil sweep`: a grid over trigger thresholds (eta, r) and link conditions (delay, jitter, loss), each point a
lockstep session in its own process, `--jobs` at a time; writes DIR/sweep.csv, DIR/pareto.png and DIR/sweep.md."""
from __future__ import annotations

import argparse
import os
import shlex
import sys
import time
from pathlib import Path

from sea_hil.commands.common import add_scenario_args
from sea_hil.errors import ConfigError
from sea_hil.sweep.grid import DIRECTIONS, expand_grid, parse_axis


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("sweep", help="grid over trigger thresholds and link conditions, in parallel lockstep runs",
                       description="Run one lockstep session per grid point (eta x r x delay x jitter x loss, ET) "
                                   "plus one TT reference per link condition, --jobs at a time; write DIR/sweep.csv, "
                                   "DIR/pareto.png (transmissions vs max tracking error) and DIR/sweep.md.")
    p.add_argument("--out", required=True, type=Path, metavar="DIR", help="output directory")
    p.add_argument("--config", metavar="FILE", help="base TOML overlaid on the embedded defaults")
    p.add_argument("--eta", default="0.3,0.5,0.8", help="trigger eta values, comma-separated (default %(default)s)")
    p.add_argument("--r", default="0.1,0.2", help="trigger r values (default %(default)s)")
    p.add_argument("--delay-ms", default="0,10", help="link delay values [ms] (default %(default)s)")
    p.add_argument("--jitter-ms", default="0", help="link jitter values [ms] (default %(default)s)")
    p.add_argument("--loss", default="0", help="link loss probabilities in [0, 1] (default %(default)s)")
    p.add_argument("--link", choices=DIRECTIONS, default="both",
                   help="which direction(s) the link condition impairs (default %(default)s: states up and "
                        "setpoints down, each with the full delay/jitter/loss)")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="points run in parallel (default: CPUs)")
    p.add_argument("--cycles", type=int, default=1, help="walking cycles per point (default %(default)s)")
    p.add_argument("--seed", type=int, help="seed for every point's RNGs (same for all points: paired comparison)")
    p.add_argument("--mode", choices=("lockstep", "offline"), default="lockstep",
                   help="lockstep = `sea-hil run --lockstep` per point; offline = `sea-hil simulate` (no network, "
                        "so delay/jitter/loss must be 0)")
    add_scenario_args(p)
    p.set_defaults(func=_main)


def _command_line(args: argparse.Namespace) -> str:
    """The effective command (every grid option spelled out), for sweep.md."""
    parts = ["sea-hil", "sweep", "--out", str(args.out), "--mode", args.mode, "--eta", args.eta, "--r", args.r,
             "--delay-ms", args.delay_ms, "--jitter-ms", args.jitter_ms, "--loss", args.loss, "--link", args.link,
             "--jobs", str(args.jobs), "--cycles", str(args.cycles)]
    parts += ["--config", args.config] if args.config else []
    parts += ["--disturbance", args.disturbance] if args.disturbance else []
    parts += ["--mismatch", args.mismatch] if args.mismatch else []
    return shlex.join(parts + (["--seed", str(args.seed)] if args.seed is not None else []))


def _main(args: argparse.Namespace) -> int:
    from sea_hil.sweep.runner import SweepOptions, build_configs, run_sweep
    from sea_hil.sweep.output import write_outputs
    axes = {name: parse_axis(name, getattr(args, name.replace("-", "_"))) for name in
            ("eta", "r", "delay-ms", "jitter-ms", "loss")}
    if args.jobs < 1:
        raise ConfigError(f"--jobs must be >= 1, not {args.jobs}")
    if args.cycles < 1:
        raise ConfigError(f"--cycles must be >= 1, not {args.cycles}")
    if args.mode == "offline" and any(v != 0 for name in ("delay-ms", "jitter-ms", "loss") for v in axes[name]):
        raise ConfigError("--mode offline has no network: --delay-ms, --jitter-ms and --loss must be 0")
    points = expand_grid(axes["eta"], axes["r"], axes["delay-ms"], axes["jitter-ms"], axes["loss"])
    opts = SweepOptions(out=args.out, config=Path(args.config) if args.config else None, mode=args.mode,
                        cycles=args.cycles, seed=args.seed, jobs=args.jobs, direction=args.link,
                        disturbance=args.disturbance, mismatch=args.mismatch)
    configs = build_configs(points, opts)
    command = _command_line(args)
    log = lambda s: print(s, file=sys.stderr, flush=True)  # noqa: E731
    log(f"sweep: {len(points)} points ({sum(p.controller == 'et' for p in points)} ET + "
        f"{sum(p.controller == 'tt' for p in points)} TT references), {args.jobs} jobs, mode {args.mode} -> {args.out}")
    t0 = time.monotonic()
    rows, interrupted = run_sweep(points, opts, log, configs)
    wall_s = time.monotonic() - t0
    write_outputs(args.out, rows, command, wall_s, args.jobs, args.mode, interrupted)
    ok = sum(r["status"] == "ok" for r in rows)
    log(f"sweep: {ok}/{len(rows)} points ok in {wall_s:.1f} s -> {args.out / 'sweep.csv'}, "
        f"{args.out / 'pareto.png'}, {args.out / 'sweep.md'}")
    if interrupted:
        raise KeyboardInterrupt
    return 0 if ok == len(rows) else 1
