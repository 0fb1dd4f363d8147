#!/usr/bin/env python3
"""A controller on the CAN bus of sea-hil's emulated SEA driver, as a user's embedded controller would run it: python-can
and the DBC (cantools) only, no edge, nothing of sea-hil's Python. Per driver sample (the three FEEDBACK frames of
one `seq`): the ET-SMC outer loop every `controller.sample_period_s` (../external_controller/etsmc.py: gait, lead-in,
trigger, SMC), the backstepping inner loop (can_backstepping.py) every sample, one VOLTAGE_CMD carrying the sample's
`seq`. Heartbeats are watched: a FAULT (e.g. the watchdog tripped) is cleared with CLEAR_ERRORS.

    sea-hil plant --can socketcan:vcan0 --config cfg.toml [--lockstep] &
    python examples/can_controller/controller.py --interface socketcan --channel vcan0 --config cfg.toml

`--config` is a complete sea-hil config TOML (`sea-hil run` writes one as DIR/config.toml). The summary (tracking
error over the cycles at the outer rate, like sea-hil's summary.json, and counters) is printed as JSON.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
import tomllib
from pathlib import Path
from typing import Any

import can
import cantools

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent / "external_controller")]
from can_backstepping import InnerLoop  # noqa: E402
from etsmc import OuterLoop  # noqa: E402  (the outer loop shared with the Zenoh example)

DEFAULT_DBC = Path(__file__).resolve().parents[2] / "protocol" / "sea.dbc"
CMD_BITS, CMD_MASK = 5, 0x1F
FEEDBACK = ("FEEDBACK_ANGLE", "FEEDBACK_JOINT1", "FEEDBACK_JOINT2")
FAULT = 2


class CanController:
    def __init__(self, cfg: dict[str, Any], db: Any, bus: can.BusABC, *, node_id: int = 1, cycles: int = 1,
                 mode: str = "et") -> None:
        self.db, self.bus, self.node_id = db, bus, node_id
        self.outer = OuterLoop(cfg, cycles, mode)
        self.inner = InnerLoop(cfg, self.outer.limb)
        rate = cfg["can"]["feedback_rate_hz"]
        self.period_ns = int(round(1e9 / rate))
        self.outer_every = max(1, int(round(cfg["controller"]["sample_period_s"] * rate)))
        self.cmd = db.get_message_by_name("VOLTAGE_CMD")
        self.clear = db.get_message_by_name("CLEAR_ERRORS")
        self._parts: dict[str, dict[str, float]] = {}
        self._seq: int | None = None
        self._t_us: int | None = None
        self._last_cmd: can.Message | None = None
        self.done = False
        self.errors: dict[str, list[float]] = {"cycle": [0.0, 0.0], "lead_in": [0.0, 0.0]}
        self._sq = [0.0, 0.0]
        self._n_cycle = 0
        self._t_full_us = 0
        self.counts = {"samples": 0, "outer": 0, "events": 0, "commands": 0, "resent_commands": 0, "rejected": 0,
                       "clear_errors": 0, "foreign": 0}

    def on_message(self, msg: can.Message) -> None:
        """One received frame; a completed feedback sample is answered with a VOLTAGE_CMD."""
        if msg.is_extended_id or msg.is_error_frame or msg.is_remote_frame:
            self.counts["rejected"] += 1
            return
        if msg.arbitration_id >> CMD_BITS != self.node_id:
            self.counts["foreign"] += 1
            return
        try:
            m = self.db.get_message_by_frame_id(msg.arbitration_id)
            sig = m.decode(bytes(msg.data), decode_choices=False)
        except (KeyError, ValueError, cantools.database.DecodeError):
            self.counts["rejected"] += 1
            return
        if m.name == "HEARTBEAT":
            if sig["state"] == FAULT and not self.done:     # e.g. the watchdog tripped: clear, command again
                self._send(self.clear, {})
                self.counts["clear_errors"] += 1
        elif m.name in FEEDBACK:
            if sig["seq"] != self._seq:
                self._seq, self._parts = sig["seq"], {}
            self._parts[m.name] = sig
            if len(self._parts) == 3:
                self._on_sample(self._parts)
                self._parts = {}

    def _send(self, message: Any, signals: dict[str, float]) -> can.Message:
        frame = can.Message(arbitration_id=self.node_id << CMD_BITS | (message.frame_id & CMD_MASK),
                            data=message.encode(signals), is_extended_id=False)
        self.bus.send(frame)
        return frame

    def _on_sample(self, p: dict[str, dict[str, float]]) -> None:
        a, j1, j2 = (p[n] for n in FEEDBACK)
        if self._last_cmd is not None and a["seq"] == self._last_cmd.data[0] and a["t_us"] == self._t_us:
            self.bus.send(self._last_cmd)       # the driver re-sent a sample we answered (lockstep): same answer
            self.counts["resent_commands"] += 1
            return
        prev = self._t_us
        self._t_us = a["t_us"]
        self._t_full_us = a["t_us"] if prev is None else self._t_full_us + ((a["t_us"] - prev) & 0xFFFF)
        now_ns = self._t_full_us * 1000
        theta, omega = (a["theta1"], a["theta2"]), (j1["omega1"], j2["omega2"])
        self.counts["samples"] += 1
        if round(now_ns / self.period_ns) % self.outer_every == 0 and not self.done:
            self._outer(now_ns, theta, omega)
        if self.done:
            return      # past the cycles: stop commanding (the driver's watchdog takes it to its safe state)
        u = self.inner.voltage((*theta, *omega, j1["delta1"], j2["delta2"], j1["nut_vel1"], j2["nut_vel2"]))
        self._last_cmd = self._send(self.cmd, {"seq": a["seq"], "voltage1": u[0], "voltage2": u[1]})
        self.counts["commands"] += 1

    def _outer(self, now_ns: int, theta: tuple[float, float], omega: tuple[float, float]) -> None:
        try:
            d = self.outer.step(now_ns, theta, omega)
        except (ArithmeticError, ValueError):
            self.counts["rejected"] += 1
            return
        if d is None:
            self.done = True
            return
        self.counts["outer"] += 1
        if d.reason is not None:
            self.inner.hold(d.deflection_m, d.sliding)
            self.counts["events"] += 1
        phase = "lead_in" if d.t_ns < 0 else "cycle"
        for j in (0, 1):
            err = abs(theta[j] - d.desired[0][j])
            self.errors[phase][j] = max(self.errors[phase][j], err)
            if phase == "cycle":
                self._sq[j] += err * err
        self._n_cycle += phase == "cycle"

    def run(self, timeout_s: float | None = None) -> bool:
        """Handle frames until the cycles are done (True) or `timeout_s` of wall time passed (False)."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while not self.done and (deadline is None or time.monotonic() < deadline):
            msg = self.bus.recv(timeout=0.05)
            if msg is not None:
                self.on_message(msg)
        return self.done

    def summary(self) -> dict[str, Any]:
        n = max(1, self._n_cycle)
        return {"done": self.done, "max_abs_error_rad": self.errors["cycle"],
                "rms_error_rad": [math.sqrt(v / n) for v in self._sq], "lead_in_max_abs_error_rad": self.errors["lead_in"],
                **self.counts}


def load_dbc(path: Path) -> Any:
    """The DBC holds node 1's ids; masked to the command bits, one definition decodes every node."""
    return cantools.database.load_file(str(path), frame_id_mask=CMD_MASK, strict=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--interface", default="socketcan", help="python-can interface (socketcan, virtual, ...)")
    ap.add_argument("--channel", default="vcan0")
    ap.add_argument("--config", type=Path, required=True, help="complete sea-hil config TOML")
    ap.add_argument("--dbc", type=Path, default=DEFAULT_DBC)
    ap.add_argument("--node", type=int, default=1, help="driver node id")
    ap.add_argument("--cycles", type=int, default=1)
    ap.add_argument("--mode", choices=("et", "tt"), default="et")
    ap.add_argument("--timeout", type=float, default=None, metavar="S")
    args = ap.parse_args(argv)
    cfg = tomllib.loads(args.config.read_text(encoding="utf-8"))
    with can.Bus(interface=args.interface, channel=args.channel) as bus:
        try:
            node = CanController(cfg, load_dbc(args.dbc), bus, node_id=args.node, cycles=args.cycles, mode=args.mode)
        except (KeyError, ValueError) as err:     # e.g. a CSV trajectory, an incomplete config
            print(f"controller.py: error: unusable config {args.config}: {err}", file=sys.stderr)
            return 2
        done = node.run(args.timeout)
    print(json.dumps(node.summary()))
    return 0 if done else 3


if __name__ == "__main__":
    sys.exit(main())
