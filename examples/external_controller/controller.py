#!/usr/bin/env python3
"""An ET-SMC remote controller from outside sea-hil: joins `sea-hil run --controller external` over Zenoh using only
`zenoh`, `struct`, the standard library, the payload layout file (protocol/payloads.toml) and the session's config
TOML. The control law is in etsmc.py next to this file; the protocol is docs/external-controller.md.

    sea-hil run --controller external --lockstep --out /tmp/ext     # prints the endpoint and the config path
    python examples/external_controller/controller.py --connect tcp/127.0.0.1:PORT --config /tmp/ext/config.toml \
        --lockstep

Per state: trigger and SMC (a SETPOINT only on events), a JSON tracking record on the `event` key and, in lockstep,
an ACK on the `control` key; a re-sent state gets the same answer again. Exits 0 after `--cycles` cycles, 3 on
`--timeout`. Counters are printed as JSON on stderr at exit.
"""
from __future__ import annotations

import argparse
import json
import math
import queue
import secrets
import struct
import sys
import threading
import time
import tomllib
from pathlib import Path
from typing import Any

import zenoh
from etsmc import OuterLoop

DEFAULT_LAYOUT = Path(__file__).resolve().parents[2] / "protocol" / "payloads.toml"
U32 = 0xFFFF_FFFF


class Wire:
    """Payload encoding/decoding from the layout file: header + body struct formats, type ids, reason values."""

    def __init__(self, layout: dict[str, Any]) -> None:
        self.magic, self.version = layout["magic"].encode(), layout["version"]
        self.header = struct.Struct(layout["header"]["format"])
        self.header_names = [f["name"] for f in layout["header"]["fields"]]
        self.epoch = secrets.randbits(64) | 1     # this controller's session epoch: random per start, never 0
        self.msgs = {m["name"]: m for m in layout["message"]}
        self.body = {name: struct.Struct(m["format"]) for name, m in self.msgs.items()}
        self.by_id = {m["type_id"]: name for name, m in self.msgs.items()}
        self.reasons = layout["enums"]["reason"]

    def decode(self, data: bytes) -> tuple[str, int, dict[str, Any]] | None:
        """(type name, seq, fields by name, the header's `epoch` among them) or None for anything malformed (magic,
        version, type, length, NaN)."""
        if len(data) < self.header.size:
            return None
        head = dict(zip(self.header_names, self.header.unpack_from(data), strict=True))
        name = self.by_id.get(head["type"])
        if head["magic"] != self.magic or head["version"] != self.version or name is None \
                or len(data) != self.msgs[name]["size"]:
            return None
        values, out = list(self.body[name].unpack_from(data, self.header.size)), {"epoch": head["epoch"]}
        if not all(math.isfinite(v) for v in values if isinstance(v, float)):
            return None         # NaN/inf: rejected like sea-hil's own decoder does
        for f in self.msgs[name]["fields"]:
            n = f.get("count", 1)
            out[f["name"]] = tuple(values[:n]) if n > 1 else values[0]
            del values[:n]
        return name, head["seq"], out

    def encode(self, name: str, seq: int, *body: Any) -> bytes:
        head = {"magic": self.magic, "version": self.version, "type": self.msgs[name]["type_id"], "seq": seq,
                "t_ns": time.monotonic_ns(), "epoch": self.epoch}
        return self.header.pack(*(head[n] for n in self.header_names)) + self.body[name].pack(*body)


class ExternalController:
    def __init__(self, cfg: dict[str, Any], wire: Wire, session: zenoh.Session, *, lockstep: bool, cycles: int,
                 mode: str) -> None:
        self.wire, self.lockstep = wire, lockstep
        self.outer = OuterLoop(cfg, cycles, mode)
        base = f"{cfg['zenoh']['prefix']}/{cfg['zenoh']['limb']}"
        # real time: DROP (a late answer is worth less than the next); lockstep: BLOCK, so no subscriber (a recorder)
        # misses an answer (docs/zenoh-protocol.md)
        congestion = zenoh.CongestionControl.BLOCK if lockstep else zenoh.CongestionControl.DROP
        pub = dict(express=True, priority=zenoh.Priority.REAL_TIME, congestion_control=congestion)
        self.sp_pub = session.declare_publisher(f"{base}/setpoint", **pub)
        self.ack_pub = session.declare_publisher(f"{base}/control", **pub)
        self.event_pub = session.declare_publisher(f"{base}/event", express=False,
                                                   congestion_control=zenoh.CongestionControl.BLOCK)
        # lockstep: every state, in order (FIFO); real time: the newest only (a slot overwritten on arrival)
        self._fifo: queue.SimpleQueue[bytes] = queue.SimpleQueue()
        self._newest: bytes | None = None
        self._cond = threading.Condition()
        self.sub = session.declare_subscriber(f"{base}/state", self._on_state)
        self.last_seq: int | None = None
        self.edge_epoch: int | None = None      # learned from the first state (docs/zenoh-protocol.md, epoch)
        self.last_answer: tuple[int, list[tuple[Any, bytes]]] | None = None
        self.setpoint_seq = 0
        self.done = False
        self.counts = {"states": 0, "setpoints": 0, "rejected": 0, "ignored": 0, "resent_answers": 0, "unusable": 0,
                       "foreign_epoch": 0}

    def _on_state(self, sample: zenoh.Sample) -> None:
        data = sample.payload.to_bytes()
        if self.lockstep:
            self._fifo.put(data)
            return
        with self._cond:
            self._newest = data
            self._cond.notify()

    def next_state(self, timeout_s: float) -> bytes | None:
        if self.lockstep:
            try:
                return self._fifo.get(timeout=timeout_s)
            except queue.Empty:
                return None
        with self._cond:
            self._cond.wait_for(lambda: self._newest is not None, timeout_s)
            data, self._newest = self._newest, None
            return data

    def run(self, timeout_s: float | None) -> bool:
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while not self.done and (deadline is None or time.monotonic() < deadline):
            data = self.next_state(0.05)
            if data is not None:
                self.handle(data)
        return self.done

    def handle(self, data: bytes) -> None:
        msg = self.wire.decode(data)
        if msg is None or msg[0] != "STATE":
            self.counts["rejected"] += 1
            return
        _, seq, st = msg
        if self.edge_epoch is None:
            self.edge_epoch = st["epoch"]
        elif st["epoch"] != self.edge_epoch:   # another session's state (a replay) or a second sender: ignored
            self.counts["foreign_epoch"] += 1
            return
        ahead = None if self.last_seq is None else (seq - self.last_seq) & U32   # serial arithmetic, wraps
        if ahead == 0:          # a state seen before: in lockstep the edge re-sends one it is waiting for
            if self.lockstep and self.last_answer is not None and self.last_answer[0] == seq:
                for pub, payload in self.last_answer[1]:
                    pub.put(payload)
                self.counts["resent_answers"] += 1
            return
        if ahead is not None and ahead >= 1 << 31:
            self.counts["ignored"] += 1     # older than the newest one: stale, ignored
            return
        self.last_seq = seq
        theta, omega = st["theta_rad"], st["omega_rad_s"]
        try:
            d = self.outer.step(st["sample_t_ns"], theta, omega)
        except (ArithmeticError, ValueError):   # an absurd (finite) state: count it, answer nothing
            self.counts["unusable"] += 1
            return
        if d is None:           # past the measured cycles: leave it unanswered, stop
            self.done = True
            return
        reason, des = d.reason, d.desired
        answer: list[tuple[Any, bytes]] = []
        if reason is not None:
            self.setpoint_seq += 1
            answer.append((self.sp_pub, self.wire.encode("SETPOINT", self.setpoint_seq, seq, *d.deflection_m,
                                                          *d.sliding, self.wire.reasons[reason])))
        if self.lockstep:
            sent = reason is not None
            answer.append((self.ack_pub, self.wire.encode("ACK", seq, seq, self.setpoint_seq if sent else 0,
                                                          int(sent))))
        for pub, payload in answer:     # the setpoint before the ACK that announces it
            pub.put(payload)
        self.last_answer = (seq, answer)
        self.counts["states"] += 1
        self.counts["setpoints"] = self.setpoint_seq
        self.event_pub.put(json.dumps({
            "t_s": d.t_ns * 1e-9, "state_seq": seq, "theta1_rad": theta[0], "theta2_rad": theta[1],
            "theta1_d_rad": des[0][0], "theta2_d_rad": des[0][1], "event": reason is not None,
            "reason": reason or "", "setpoint_seq": self.setpoint_seq if reason is not None else 0}).encode())


def zenoh_config(connect: list[str]) -> zenoh.Config:
    zc = zenoh.Config()
    zc.insert_json5("mode", json.dumps("peer"))
    zc.insert_json5("scouting/multicast/enabled", "false")
    zc.insert_json5("connect/endpoints", json.dumps(connect))
    return zc


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--connect", action="append", required=True, metavar="ENDPOINT", help="e.g. tcp/127.0.0.1:7447")
    ap.add_argument("--config", type=Path, required=True, help="the session's config TOML (sea-hil run: DIR/config.toml)")
    ap.add_argument("--layout", type=Path, default=DEFAULT_LAYOUT, help="payload layout TOML (protocol/payloads.toml)")
    ap.add_argument("--cycles", type=int, default=1, help="measured cycles, as given to sea-hil run")
    ap.add_argument("--lockstep", action="store_true", help="the session runs with --lockstep: ACK every state")
    ap.add_argument("--mode", choices=("et", "tt"), default="et", help="event- or time-triggered")
    ap.add_argument("--timeout", type=float, default=None, metavar="S", help="give up after S seconds")
    args = ap.parse_args(argv)
    cfg = tomllib.loads(args.config.read_text(encoding="utf-8"))
    wire = Wire(tomllib.loads(args.layout.read_text(encoding="utf-8")))
    session = zenoh.open(zenoh_config(args.connect))
    try:
        node = ExternalController(cfg, wire, session, lockstep=args.lockstep, cycles=args.cycles, mode=args.mode)
    except (KeyError, ValueError) as err:     # e.g. a CSV trajectory, an incomplete config
        session.close()
        print(f"controller.py: error: unusable config {args.config}: {err}", file=sys.stderr)
        return 2
    try:
        done = node.run(args.timeout)
    finally:
        node.sub.undeclare()
        session.close()
    print(json.dumps({"done": done, **node.counts}), file=sys.stderr)
    return 0 if done else 3


if __name__ == "__main__":
    sys.exit(main())
