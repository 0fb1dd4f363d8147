"""Options shared by several subcommands, and turning them into a frozen config."""
from __future__ import annotations

import argparse
import math
from typing import Any

from sea_hil.config.root import SeaHilConfig
from sea_hil.config.shorthand import scenario_config
from sea_hil.errors import ConfigError
from sea_hil.input_check import enforce
from sea_hil.protocol.link import parse_link_spec


def add_config_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", metavar="FILE", help="TOML file overlaid on the embedded defaults")
    p.add_argument("--seed", type=int, help="seed for every RNG (link emulation, disturbance noise)")
    p.add_argument("--allow-unsafe-start", action="store_true",
                   help="run a config whose start pose or trajectory leaves the drive's soft limits, the end stops or "
                        "the setpoint envelope (refused at load otherwise; `sea-hil check` says why): sets [verdict] "
                        "check_inputs = false; such a run's verdict says what happened")


def add_strict_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--strict", action="store_true",
                   help="exit status 3 when the verdict (summary.json `verdict`, docs/verdict.md) is not ok")


def add_zenoh_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--connect", action="append", default=[], metavar="ENDPOINT",
                   help="Zenoh endpoint to connect to, e.g. tcp/10.0.0.2:7447 (repeatable)")
    p.add_argument("--listen", action="append", default=[], metavar="ENDPOINT",
                   help="Zenoh endpoint to listen on, e.g. tcp/0.0.0.0:7447 (repeatable)")
    p.add_argument("--limb", help="limb name in the Zenoh keys (default from config: limb1)")
    p.add_argument("--mode", choices=("peer", "client"),
                   help="Zenoh mode (zenoh.mode; default from config: peer; `record` with only --connect: client, "
                        "docs/topologies.md)")


def add_link_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--uplink", metavar="SPEC", help="link emulation edge->controller, e.g. 'delay=20ms,jitter=5ms,"
                                                    "loss=1%%,ge=0.01/0.3/0.8,rate=1Mbps'")
    p.add_argument("--downlink", metavar="SPEC", help="link emulation controller->edge (same syntax)")


def add_scenario_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--disturbance", metavar="SPEC",
                   help="disturbance torques per joint, e.g. 'knee=sine:0.05Nm@2Hz,hip=constant:0.5Nm', "
                        "'noise:0.05Nm@10ms' (no joint: both); replaces [disturbance.hip]/[disturbance.knee]")
    p.add_argument("--mismatch", metavar="SPEC",
                   help="controller's nominal model vs the plant, e.g. 'mass=+20%%,stiffness=-20%%' (groups mass, "
                        "inertia, stiffness, damping, all; or m1, m2, i1, i2, k1, k2, b1, b2); sets [controller.model]")


def add_period_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--period-ms", type=float, metavar="P",
                   help="outer sample period on the wire [ms] (controller.sample_period_s; the inner loop stays at "
                        "can.feedback_rate_hz): periodic baselines at reduced rates, e.g. --controller tt "
                        "--period-ms 30; a positive multiple of the inner period")


def check_period_ms(period_ms: float, cfg: SeaHilConfig, option: str = "--period-ms") -> float:
    """`period_ms` as `controller.sample_period_s` [s], or a ConfigError: not a positive finite number, or not a
    whole multiple of the inner-loop period of `cfg` (1 / can.feedback_rate_hz)."""
    if not math.isfinite(period_ms) or period_ms <= 0:
        raise ConfigError(f"{option} {period_ms:g}: must be a positive number of milliseconds")
    inner_ms = 1000.0 / cfg.can.feedback_rate_hz
    steps = period_ms / inner_ms
    if abs(steps - round(steps)) > 1e-9:
        raise ConfigError(f"{option} {period_ms:g}: must be a whole multiple of the inner-loop period "
                          f"{inner_ms:g} ms (1 / can.feedback_rate_hz)")
    return period_ms / 1000.0


def add_scheme_args(p: argparse.ArgumentParser) -> None:
    """Issue 16: where the trigger runs and whether the controller compensates the link delay (default: config)."""
    p.add_argument("--trigger", choices=("edge", "controller"),
                   help="trigger placement (trigger.placement): 'edge' = the edge publishes a state only on an event "
                        "(both directions event-triggered), 'controller' = the paper's (every state up)")
    p.add_argument("--compensation", choices=("predict", "none"),
                   help="delay compensation (controller.compensation): 'predict' = v_x for the state predicted at "
                        "the instant the setpoint acts, 'none' = the paper's")


def _paper_scheme_where_needed(args: argparse.Namespace, ov: dict[str, Any]) -> None:
    """The paper's scheme where the default one cannot work: `--inner remote` needs a state every sample (the
    voltage is computed per state) and the predictor models the edge's inner loop, so it runs the trigger at the
    controller without compensation; `--controller external` speaks the documented STATE protocol (every state up,
    docs/external-controller.md), so it runs the trigger at the controller. An explicit `--trigger edge` with
    `--inner remote` is a ConfigError; with `external` it is the user's choice."""
    remote, external = getattr(args, "inner", None) == "remote", getattr(args, "controller", None) == "external"
    if remote and getattr(args, "trigger", None) == "edge":
        raise ConfigError("--inner remote computes the voltage from every state: it needs --trigger controller")
    if (remote or external) and not getattr(args, "trigger", None):
        ov.setdefault("trigger", {})["placement"] = "controller"
    if remote and not getattr(args, "compensation", None):
        ov.setdefault("controller", {})["compensation"] = "none"


def config_from_args(args: argparse.Namespace, overrides: dict[str, Any] | None = None, *,
                     check: str | None = None) -> SeaHilConfig:
    """The config of a command's options; `check` = "session" or "offline": its inputs checked before anything moves
    (sea_hil/input_check.py: ConfigError, exit 2), None: not checked (the single-node commands)."""
    ov: dict[str, Any] = dict(overrides or {})
    if getattr(args, "allow_unsafe_start", False):   # carried in the config: a session's children see it too
        ov["verdict"] = {**ov.get("verdict", {}), "check_inputs": False}
    if getattr(args, "seed", None) is not None:
        ov.setdefault("link", {})["seed"] = args.seed
        ov.setdefault("disturbance", {})["seed"] = args.seed
    if getattr(args, "trigger", None):
        ov.setdefault("trigger", {})["placement"] = args.trigger
    if getattr(args, "compensation", None):
        ov.setdefault("controller", {})["compensation"] = args.compensation
    _paper_scheme_where_needed(args, ov)
    if getattr(args, "trajectory", None):
        ov.setdefault("trajectory", {}).update({"kind": "csv", "csv_path": args.trajectory})
    for direction in ("uplink", "downlink"):
        spec = getattr(args, direction, None)
        if spec:
            ov.setdefault("link", {})[direction] = parse_link_spec(spec)
    z: dict[str, Any] = {}
    if getattr(args, "connect", None):
        z["connect"] = list(args.connect)
    if getattr(args, "listen", None):
        z["listen"] = list(args.listen)
    if getattr(args, "limb", None):
        z["limb"] = args.limb
    if getattr(args, "mode", None):
        z["mode"] = args.mode
    if z:
        ov["zenoh"] = {**ov.get("zenoh", {}), **z}
    if getattr(args, "can", None):
        ov.setdefault("can", {})["interface"] = args.can
    def build(o: dict[str, Any]) -> SeaHilConfig:
        return scenario_config(getattr(args, "config", None), o, getattr(args, "disturbance", None),
                               getattr(args, "mismatch", None))
    cfg = build(ov)
    period_ms = getattr(args, "period_ms", None)
    if period_ms is not None:
        ctrl = {**ov.get("controller", {}), "sample_period_s": check_period_ms(period_ms, cfg)}
        cfg = build({**ov, "controller": ctrl})
    if check is None:
        return cfg
    return enforce(cfg, offline=check == "offline")
