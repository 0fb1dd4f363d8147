"""`sea-hil robustness`: max / RMS tracking error and transmissions against disturbance amplitude and model
mismatch, TT and ET (offline closed loop): DIR/robustness.csv, DIR/robustness.png, DIR/robustness.md."""
from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path
from typing import Any

from sea_hil.errors import ConfigError
from sea_hil.offline.robustness import grid, run_grid
from sea_hil.offline.robustness_output import write_csv, write_figure, write_markdown


def _floats(name: str, text: str) -> tuple[float, ...]:
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError as err:
        raise ConfigError(f"--{name} {text!r}: not a comma-separated list of numbers") from err
    return vals


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("robustness", help="error and transmissions vs disturbance amplitude and model mismatch",
                       description="Offline closed loop (CAN-quantised) for TT and ET over disturbance amplitude "
                                   "(constant, 0.5 Hz / 2 Hz sine, held noise; both joints, scale 1 = 0.5 N m hip, "
                                   "0.05 N m knee) and over the nominal model's mass / inertia / stiffness mismatch.")
    p.add_argument("--out", required=True, type=Path, metavar="DIR", help="output directory")
    p.add_argument("--config", metavar="FILE", help="TOML overlaid on the embedded defaults (e.g. configs/paper.toml)")
    p.add_argument("--trajectory", metavar="CSV", help="desired trajectory CSV (t, theta1, theta2)")
    p.add_argument("--scales", default="0,0.25,0.5,0.75,1", help="disturbance amplitude scales (default %(default)s)")
    p.add_argument("--percents", default="-20,-10,0,10,20",
                   help="mismatch percentages (default %(default)s; write --percents=-20,20 for a leading minus)")
    p.add_argument("--settle-s", type=float, default=0.5,
                   help="errors over t >= this (default %(default)s s: the offline start is its own transient)")
    p.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    ov: dict[str, Any] = {}
    if args.trajectory:
        ov["trajectory"] = {"kind": "csv", "csv_path": args.trajectory}
    points = grid(_floats("scales", args.scales), _floats("percents", args.percents))
    args.out.mkdir(parents=True, exist_ok=True)
    if args.settle_s < 0:
        raise ConfigError(f"--settle-s must be >= 0, not {args.settle_s}")
    rows = run_grid(points, args.config, ov, args.settle_s, log=lambda s: print(s, file=sys.stderr, flush=True))
    write_csv(args.out / "robustness.csv", rows)
    write_figure(args.out / "robustness.png", rows)
    parts = ["sea-hil", "robustness", "--out", str(args.out), f"--scales={args.scales}", f"--percents={args.percents}",
             "--settle-s", f"{args.settle_s:g}"]
    parts += ["--config", args.config] if args.config else []
    parts += ["--trajectory", args.trajectory] if args.trajectory else []
    command = shlex.join(parts)
    write_markdown(args.out / "robustness.md", rows, command)
    print((args.out / "robustness.md").read_text(encoding="utf-8"))
    return 0
