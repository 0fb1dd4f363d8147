"""What `sea-hil edge` and `sea-hil controller` share: the options of a Zenoh node of a session (inner-loop
placement, lockstep, Zenoh endpoints, live view, config, scheme) and the session it runs in (the builder, its Zenoh
session and, with `--foxglove`, the `sea-hil record` child serving the live view)."""
from __future__ import annotations

import argparse
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from sea_hil.commands.common import add_config_args, add_link_args, add_scheme_args, add_zenoh_args, config_from_args
from sea_hil.live.child import attach_live_child
from sea_hil.live.cli import add_live_args, live_overrides
from sea_hil.report.node_summary import node_summary, print_node_summary
from sea_hil.runtime.realtime import node_priority, raise_node_process
from sea_hil.session.builder import SessionBuilder


def add_node_args(p: argparse.ArgumentParser, *, link: bool = False) -> None:
    """The options after the node's own; `link`: also `--uplink` / `--downlink` emulation."""
    p.add_argument("--inner", choices=("edge", "remote"), default="edge",
                   help="where the voltage loop runs: edge (next to the CAN bus, default) or remote (the controller)")
    p.add_argument("--lockstep", action="store_true",
                   help="advance in simulated time, one sample per answered message (deterministic)")
    add_zenoh_args(p)
    if link:
        add_link_args(p)
    add_live_args(p, node=True)
    add_config_args(p)
    add_scheme_args(p)
    add_json_arg(p)


def add_json_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true",
                   help="at the end print the node's summary as JSON (one line) instead of its table")
    p.add_argument("--no-result", action="store_true",
                   help="print no result at the end (`sea-hil run`'s own children: run prints the session's)")


def print_result(args: argparse.Namespace, kind: str, counters: dict[str, Any], finished: bool) -> None:
    """The node's own result at its end (`sea_hil.report.node_summary`); nothing with `--no-result`."""
    if args.no_result:
        return
    print_node_summary(node_summary(kind, counters, finished=finished), as_json=args.json, command=args.command)


@contextmanager
def node_session(args: argparse.Namespace, role: str) -> Iterator[tuple[Any, Any, Any]]:
    """(builder, config, Zenoh session) of one node process (`role`: edge or controller), closed on exit. The edge's
    live-view recorder child also records its CAN bus. A real-time controller of its own (the compose topology;
    `sea-hil run` sets it for its children) takes SCHED_FIFO two below the driver after its start-up
    (`node_priority`, `RealTimeControllerSync.state_source`); the edge raises its loop once built (`raise_node`)."""
    cfg = config_from_args(args, live_overrides(args))
    if role == "controller" and not args.lockstep and not cfg.timing.controller_priority:
        priority = node_priority(cfg.timing, role)
        if priority:
            cfg = cfg.model_copy(update={"timing": cfg.timing.model_copy(update={"controller_priority": priority})})
    with SessionBuilder(cfg, lockstep=args.lockstep) as b:
        session = b.zenoh()
        attach_live_child(b, args, cfg, cfg.can.interface if role == "edge" else None)
        yield b, cfg, session


def raise_node(args: argparse.Namespace, node: Any, cfg: Any, role: str) -> None:
    """A real-time node process of its own (the compose topology): [timing] SCHED_FIFO for its loop, one below the
    driver for the edge (`raise_node_process`)."""
    if not args.lockstep:
        raise_node_process(node, cfg.timing, role)
