"""Options shared by several subcommands, and turning them into a frozen config."""
from __future__ import annotations

import argparse
from typing import Any

from protocol.config import SeaHilConfig, load_config


def add_config_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", metavar="FILE", help="TOML file overlaid on the embedded defaults")
    p.add_argument("--seed", type=int, help="seed for every RNG (link emulation, disturbance noise)")


def config_from_args(args: argparse.Namespace, overrides: dict[str, Any] | None = None) -> SeaHilConfig:
    ov: dict[str, Any] = dict(overrides or {})
    if getattr(args, "seed", None) is not None:
        ov.setdefault("link", {})["seed"] = args.seed
        ov.setdefault("disturbance", {})["seed"] = args.seed
    if getattr(args, "trajectory", None):
        ov.setdefault("trajectory", {}).update({"kind": "csv", "csv_path": args.trajectory})
    return load_config(getattr(args, "config", None), ov)
