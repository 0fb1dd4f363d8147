"""`sea-hil sweep`: a grid over trigger thresholds (eta, r), link conditions (delay, jitter, loss) and seeds, each
point a Dask task: a run of the offline session engine (default) or a lockstep session in its own process (embedded local cluster, `--jobs` at a time, or an
existing cluster with `--scheduler`); writes DIR/sweep.csv (appended as points finish; `--resume` continues it),
DIR/pareto.png, DIR/methods.png and DIR/sweep.md."""
from __future__ import annotations

import argparse
import os
import shlex
import sys
import time
from pathlib import Path
from typing import Any

from sea_hil.commands.common import add_scenario_args, check_period_ms
from sea_hil.config.shorthand import scenario_config
from sea_hil.errors import ConfigError
from sea_hil.input_check import enforce
from sea_hil.sweep.grid import DIRECTIONS, LinkCondition, expand_grid, parse_axis, seed_axis
from sea_hil.sweep.methods import (
    COMPENSATIONS,
    METHODS,
    TRIGGERS,
    parse_choices,
    parse_links,
    schemes_from_axes,
    schemes_from_methods,
)
from sea_hil.sweep.output import write_outputs
from sea_hil.sweep.runner import SweepOptions, build_configs, run_sweep
from sea_hil.verdict.rules import STRICT_EXIT

LINK_AXIS_DEFAULTS = {"delay-ms": "0,10", "jitter-ms": "0", "loss": "0"}


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("sweep", help="grid over trigger thresholds and link conditions, in parallel lockstep runs",
                       description="Run one lockstep session per grid point (eta x r x delay x jitter x loss, ET) "
                                   "plus one TT reference per link condition, --jobs at a time; write DIR/sweep.csv, "
                                   "DIR/pareto.png (transmissions vs max tracking error) and DIR/sweep.md.")
    p.add_argument("--out", required=True, type=Path, metavar="DIR", help="output directory")
    p.add_argument("--config", metavar="FILE", help="base TOML overlaid on the embedded defaults")
    p.add_argument("--eta", default="0.3,0.5,0.8", help="trigger eta values, comma-separated (default %(default)s)")
    p.add_argument("--r", default="0.1,0.2", help="trigger r values (default %(default)s)")
    p.add_argument("--delay-ms", help=f"link delay values [ms] (default {LINK_AXIS_DEFAULTS['delay-ms']})")
    p.add_argument("--jitter-ms", help=f"link jitter values [ms] (default {LINK_AXIS_DEFAULTS['jitter-ms']})")
    p.add_argument("--loss", help=f"link loss probabilities in [0, 1] (default {LINK_AXIS_DEFAULTS['loss']})")
    p.add_argument("--links", metavar="L", help="explicit link conditions instead of delay x jitter x loss: "
                   "';'-separated link specs (the --uplink syntax) or 'ideal', or the preset issue16 (its four "
                   "links), e.g. 'ideal;delay=20ms,jitter=5ms,ge=0.01/0.3/0.8'")
    p.add_argument("--trigger", metavar="L", help="ET trigger placements: controller (the paper's), edge "
                                                  "(default: the config's trigger.placement)")
    p.add_argument("--compensation", metavar="L", help="delay compensation of every point: none, predict "
                                                       "(default: the config's controller.compensation)")
    p.add_argument("--period-ms", metavar="L", help="outer sample periods [ms] of the TT references (periodic "
                                                    "baselines at reduced rates; ET keeps the config's period)")
    p.add_argument("--methods", metavar="L", help=f"named methods instead of --trigger/--compensation: "
                   f"{', '.join(METHODS)} (TT ones at every --period-ms); docs/sweep.md, 'Methods'")
    p.add_argument("--link", choices=DIRECTIONS, default="both",
                   help="which direction(s) the link condition impairs (default %(default)s: states up and "
                        "setpoints down, each with the full delay/jitter/loss)")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="points run in parallel (default: CPUs)")
    p.add_argument("--cycles", type=int, default=1, help="walking cycles per point (default %(default)s)")
    p.add_argument("--seed", type=int, help="seed for every point's RNGs (same for all points: paired comparison); "
                                            "with --seeds the first of the seeds")
    p.add_argument("--seeds", type=int, metavar="N", help="seeds as an axis: every point under N seeds (--seed, "
                                                          "--seed + 1, ...); figures show the mean and its 95 %% band")
    p.add_argument("--scheduler", metavar="ADDRESS", help="run the points on an existing Dask cluster, e.g. "
                                                           "tcp://10.0.0.5:8786 (default: an embedded local cluster)")
    p.add_argument("--resume", action="store_true", help="keep DIR/sweep.csv and skip the points it holds as ok "
                                                         "with the same effective config")
    p.add_argument("--engine", choices=("offline", "lockstep"), default=None,
                   help="offline (default) = the offline session engine in the worker (the lockstep session's "
                        "timeline, links and quantisation; same summary, ~100x faster); lockstep = a `sea-hil run "
                        "--lockstep` session per point (the check that the real path behaves the same)")
    p.add_argument("--mode", choices=("lockstep", "offline"), default=None, help=argparse.SUPPRESS)  # old name
    p.add_argument("--allow-unsafe-start", action="store_true",
                   help="run points whose start pose, trajectory or links fail the input checks (sea-hil check)")
    p.add_argument("--strict", action="store_true",
                   help="exit status 3 at the end when a point's verdict is not ok (the list is printed)")
    add_scenario_args(p)
    p.set_defaults(func=_main)


def _command_line(args: argparse.Namespace) -> str:
    """The effective command (every grid option spelled out), for sweep.md."""
    parts = ["sea-hil", "sweep", "--out", str(args.out), "--engine", args.engine, "--eta", args.eta, "--r", args.r]
    parts += ["--links", args.links] if args.links else ["--delay-ms", args.delay_ms, "--jitter-ms", args.jitter_ms,
                                                          "--loss", args.loss]
    for opt in ("trigger", "compensation", "period_ms", "methods"):
        if getattr(args, opt):
            parts += [f"--{opt.replace('_', '-')}", getattr(args, opt)]
    parts += ["--link", args.link, "--jobs", str(args.jobs), "--cycles", str(args.cycles)]
    parts += ["--config", args.config] if args.config else []
    parts += ["--seeds", str(args.seeds)] if args.seeds is not None else []
    parts += ["--scheduler", args.scheduler] if args.scheduler else []
    parts += ["--disturbance", args.disturbance] if args.disturbance else []
    parts += ["--mismatch", args.mismatch] if args.mismatch else []
    return shlex.join(parts + (["--seed", str(args.seed)] if args.seed is not None else []))


def method_axes(args: argparse.Namespace) -> tuple[list, list, list | None]:
    """(TT schemes, ET schemes, explicit link conditions or None) from --trigger/--compensation/--period-ms,
    --methods and --links; periods checked against the base config's inner period (commands/common.py)."""
    periods = parse_axis("period-ms", args.period_ms) if args.period_ms else None
    if periods:
        base = scenario_config(args.config, {})
        for p in periods:
            check_period_ms(p, base)
    if args.methods:
        if args.trigger or args.compensation:
            raise ConfigError("--methods names whole methods: do not combine it with --trigger or --compensation")
        tt, et = schemes_from_methods(parse_choices("--methods", args.methods, tuple(METHODS)), periods)
    else:
        tt, et = schemes_from_axes(args.trigger and parse_choices("--trigger", args.trigger, TRIGGERS),
                                   args.compensation and parse_choices("--compensation", args.compensation,
                                                                       COMPENSATIONS), periods)
    links = [LinkCondition.from_spec(s) for s in parse_links(args.links)] if args.links else None
    return tt, et, links


def _main(args: argparse.Namespace) -> int:
    if args.links and any(getattr(args, n.replace("-", "_")) is not None for n in LINK_AXIS_DEFAULTS):
        raise ConfigError("--links replaces --delay-ms, --jitter-ms and --loss: give one or the other")
    for name, default in LINK_AXIS_DEFAULTS.items():
        if getattr(args, name.replace("-", "_")) is None:
            setattr(args, name.replace("-", "_"), default)
    axes = {name: parse_axis(name, getattr(args, name.replace("-", "_"))) for name in
            ("eta", "r", "delay-ms", "jitter-ms", "loss")}
    tt_schemes, et_schemes, links = method_axes(args)
    if args.jobs < 1:
        raise ConfigError(f"--jobs must be >= 1, not {args.jobs}")
    if args.cycles < 1:
        raise ConfigError(f"--cycles must be >= 1, not {args.cycles}")
    if args.mode is not None and args.engine is not None and args.mode != args.engine:
        raise ConfigError("--mode is the old name of --engine: give one of them")
    args.engine = args.engine or args.mode or "offline"
    points = expand_grid(axes["eta"], axes["r"], axes["delay-ms"], axes["jitter-ms"], axes["loss"],
                         seed_axis(args.seeds, args.seed), tt_schemes=tt_schemes, et_schemes=et_schemes, links=links)
    opts = SweepOptions(out=args.out, config=Path(args.config) if args.config else None, mode=args.engine,
                        cycles=args.cycles, seed=args.seed, jobs=args.jobs, direction=args.link,
                        scheduler=args.scheduler, resume=args.resume, disturbance=args.disturbance,
                        mismatch=args.mismatch)
    configs = build_configs(points, opts)
    configs = _checked(configs, args.allow_unsafe_start)
    command = _command_line(args)

    def log(s: str) -> None:
        print(s, file=sys.stderr, flush=True)

    where = f"cluster {args.scheduler}" if args.scheduler else f"{args.jobs} local jobs"
    log(f"sweep: {len(points)} points ({sum(p.controller == 'et' for p in points)} ET + "
        f"{sum(p.controller == 'tt' for p in points)} TT references), {where}, engine {args.engine} -> {args.out}")
    t0 = time.monotonic()
    rows, interrupted = run_sweep(points, opts, log, configs)
    wall_s = time.monotonic() - t0
    write_outputs(args.out, rows, command, wall_s, args.jobs, args.engine, interrupted)
    ok = sum(r["status"] == "ok" for r in rows)
    log(f"sweep: {ok}/{len(rows)} points ok in {wall_s:.1f} s -> {args.out / 'sweep.csv'}, "
        f"{args.out / 'pareto.png'}, {args.out / 'methods.png'}, {args.out / 'sweep.md'}")
    if interrupted:
        raise KeyboardInterrupt
    if ok != len(rows):
        return 1
    if args.strict:
        bad = [r for r in rows if r.get("verdict") != "ok"]
        for r in bad:
            log(f"sweep --strict: point {r['point']}: verdict {r.get('verdict') or 'missing'}"
                f"{': ' + r['verdict_reasons'] if r.get('verdict_reasons') else ''}")
        if bad:
            log(f"sweep --strict: {len(bad)} of {len(rows)} points not ok")
            return STRICT_EXIT
    return 0


def _checked(configs: dict[int, Any], allow_unsafe: bool) -> dict[int, Any]:
    """The points' configs after the input checks (sea_hil/input_check.py): the start pose and trajectory once (the
    points share them), links and periods per point; with `allow_unsafe`, unchecked and marked so (a lockstep
    point's `sea-hil run` reads `[verdict] check_inputs = false` from its config)."""
    if allow_unsafe:
        return {k: c.model_copy(update={"verdict": c.verdict.model_copy(update={"check_inputs": False})})
                for k, c in configs.items()}
    for i, (k, c) in enumerate(configs.items()):
        enforce(c, motion=i == 0, where=f"sweep point {k}: ")
    return configs
