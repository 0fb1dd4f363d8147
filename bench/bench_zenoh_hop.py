"""Figure 2: Zenoh hop latency through the project's publish/decode path vs a raw zenoh-python ping-pong.

Run: python -m bench.bench_zenoh_hop [--runs 5] [--pings 2000] [--secure] [--profile] [--json OUT]
This process listens on a free loopback TCP port; an echo child process (this script with `--echo`) connects.
One hop = round trip / 2, on this process's monotonic clock, in three modes; per run a fresh echo each, all open at
once, pinged in turn in blocks of 50 (so load drifts hit every mode alike):
  raw        zenoh-python defaults: declare_publisher(key), default FIFO handler with blocking recv(); 88-byte ping,
             53-byte pong of opaque bytes (the sizes of StatePayload and SetpointPayload);
  project    the real path: `encode_state` (the edge's encoder) + `sea_hil.protocol.zsession.publisher` (express,
             REAL_TIME, DROP) here; the echo receives like `controller/remote.py` (`LatestSubscriber`, newest-only),
             decodes, encodes a setpoint (`encode_setpoint`, as the controller) and publishes it; this side receives
             with blocking recv() and decodes;
  blocking   the project's payloads and publishers, but the echo uses a FIFO with blocking recv();
  tls        (`--secure` only, figure 2s) `project` over the secure profile (docs/security.md): mutual TLS with
             throwaway certificates, the ACL on both sides, pinging on the limb's `state` key as the edge's CN and
             answering on `setpoint` as the controller's CN.
`--profile` adds one mode per difference between raw and project (docs/timing.md, "Zenoh hop"): `options` (raw +
the project's publisher options), `latest` (raw + the echo's `LatestSubscriber`), `codec` (raw + the project's
payloads, encoded and decoded on both sides).
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path

import zenoh

from bench.benchlib import REPO, bench_args, emit, pct, record, stop_process, wait_ready
from sea_hil.config.comms import ZenohConfig
from sea_hil.errors import SeaHilError
from sea_hil.protocol.keys import Keys
from sea_hil.protocol.payload_hot import encode_setpoint, encode_state
from sea_hil.protocol.payloads import (
    PAYLOAD_SIZE,
    MsgType,
    PayloadCounters,
    SetpointPayload,
    StatePayload,
    TriggerReason,
)
from sea_hil.protocol.zcerts import make_certs
from sea_hil.protocol.zlatest import LatestSubscriber
from sea_hil.protocol.zsecurity import security_settings
from sea_hil.protocol.zsession import free_tcp_port, make_config, open_session, publisher

MODES = ("raw", "project", "blocking")
PROFILE_MODES = ("options", "latest", "codec")
# mode: (echo receive: fifo | latest, publishers: default | project, payloads: opaque | project)
SHAPE = {"raw": ("fifo", "default", "opaque"), "project": ("latest", "project", "project"),
         "blocking": ("fifo", "project", "project"), "tls": ("latest", "project", "project"),
         "options": ("fifo", "project", "opaque"), "latest": ("latest", "default", "opaque"),
         "codec": ("fifo", "default", "project")}
PING, PONG = "bench/hop/ping", "bench/hop/pong"
PING_BYTES, PONG_BYTES = PAYLOAD_SIZE[MsgType.STATE], PAYLOAD_SIZE[MsgType.SETPOINT]
_LIMB = Keys.make("sea", "limb1")


def _keys(mode: str) -> tuple[str, str]:
    return (_LIMB.state, _LIMB.setpoint) if mode == "tls" else (PING, PONG)


def _config(mode: str, certs: Path | None, node: str, *, listen: list[str] | tuple[str, ...] = (),
            connect: list[str] | tuple[str, ...] = ()) -> zenoh.Config:
    """Plain, or (tls) mutual TLS + ACL as `node` with the certificates in `certs`."""
    if mode != "tls" or certs is None:
        return make_config(listen=listen, connect=connect)
    z = ZenohConfig.model_validate({"tls": {"enabled": True, "root_ca_certificate": str(certs / "ca.pem"),
                                            "certificate": str(certs / f"{node}.pem"),
                                            "private_key": str(certs / f"{node}.key")}, "acl": {"enabled": True}})
    return make_config(settings=security_settings(z), listen=listen, connect=connect)
SENTINEL = b"timeout"


def _state(seq: int) -> bytes:
    return encode_state(seq, time.monotonic_ns(), seq * 1_000_000, (0.1, 0.2), (0.0, 0.0), (0.0, 0.0), (0.0, 0.0))


def _publisher(session: zenoh.Session, key: str, mode: str) -> zenoh.Publisher:
    return publisher(session, key) if SHAPE[mode][1] == "project" else session.declare_publisher(key)


def echo(endpoint: str, mode: str, certs: Path | None = None) -> int:
    """Child: answer every ping on the pong key until terminated."""
    session = open_session(_config(mode, certs, "controller", connect=[endpoint]))
    counters = PayloadCounters()
    ping, pong = _keys(mode)
    receive, _, payloads = SHAPE[mode]
    recv: Callable[[], zenoh.Sample | None]
    if receive == "latest":
        recv = partial(LatestSubscriber(session, ping).recv, 1.0)
    else:
        recv = session.declare_subscriber(ping, zenoh.handlers.FifoChannel(1024)).recv
    pub = _publisher(session, pong, mode)
    print("ready", flush=True)
    pad = bytes(PONG_BYTES - 4)
    while True:
        sample = recv()
        if sample is None:
            continue
        data = sample.payload.to_bytes()
        if payloads == "opaque":
            pub.put(data[:4] + pad)
            continue
        p = counters.try_decode(data)
        if isinstance(p, StatePayload):
            pub.put(encode_setpoint(p.seq, time.monotonic_ns(), p.seq, (0.001, 0.002), (0.0, 0.0),
                                    TriggerReason.ERROR_BOUND))


class _Watchdog:
    """Unblocks the pinger's blocking recv() with a local SENTINEL put when no pong came for `timeout_s`."""

    def __init__(self, session: zenoh.Session, timeout_s: float = 1.0, pong: str = PONG) -> None:
        self.progress_ns = time.monotonic_ns()
        self._pub = session.declare_publisher(pong)
        self._stop = threading.Event()
        self._timeout_ns = int(timeout_s * 1e9)
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(0.1):
            if time.monotonic_ns() - self.progress_ns > self._timeout_ns:
                self.progress_ns = time.monotonic_ns()
                self._pub.put(SENTINEL)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self._pub.undeclare()


def _ping_once(mode: str, seq: int, pub: zenoh.Publisher, sub: zenoh.Subscriber, counters: PayloadCounters,
               dog: _Watchdog) -> int | None:
    """Hop time in ns (round trip / 2) for ping `seq`, or None if the watchdog fired first."""
    raw_ping = seq.to_bytes(4, "little") + bytes(PING_BYTES - 4)
    t0 = time.monotonic_ns()
    opaque = SHAPE[mode][2] == "opaque"
    pub.put(raw_ping if opaque else _state(seq))
    while True:
        data = sub.recv().payload.to_bytes()
        if data == SENTINEL:
            return None
        if opaque:
            ok = int.from_bytes(data[:4], "little") == seq
        else:
            p = counters.try_decode(data)
            ok = isinstance(p, SetpointPayload) and p.state_seq == seq
        if ok:
            dog.progress_ns = t1 = time.monotonic_ns()
            return (t1 - t0) // 2


class Batch:
    """One echo child in `mode`, warmed up; `ping(n)` times n more ping-pongs (`hops` in ns, `lost`). `close()` ends
    it. Several stay open at once, so a run can alternate its modes in blocks (`_measure`)."""

    def __init__(self, mode: str, certs: Path | None = None) -> None:
        self.mode = mode
        endpoint = f"{'tls' if mode == 'tls' else 'tcp'}/127.0.0.1:{free_tcp_port()}"
        self.session = open_session(_config(mode, certs, "edge", listen=[endpoint]))
        cert_args = ["--certs", str(certs)] if mode == "tls" and certs is not None else []
        self.proc = subprocess.Popen([sys.executable, "-m", "bench.bench_zenoh_hop", "--echo", endpoint, "--mode",
                                      mode, *cert_args], cwd=REPO, stdout=subprocess.PIPE)
        ping, pong = _keys(mode)
        self.dog: _Watchdog | None = None
        self.hops: list[int] = []
        self.lost = 0
        self.seq = 0
        try:
            wait_ready(self.proc)
            self.pub = _publisher(self.session, ping, mode)
            self.sub = self.session.declare_subscriber(pong, zenoh.handlers.FifoChannel(1024))
            self.counters = PayloadCounters()
            self.dog = _Watchdog(self.session, timeout_s=0.05, pong=pong)   # warm-up: retry every ~0.1 s
            deadline = time.monotonic() + 20.0
            while _ping_once(mode, 0, self.pub, self.sub, self.counters, self.dog) is None:
                if time.monotonic() > deadline:
                    raise SeaHilError(f"no answer from the {mode} echo")
            self.dog.close()
            self.dog = _Watchdog(self.session, timeout_s=1.0, pong=pong)
        except BaseException:
            self.close()
            raise

    def ping(self, n: int) -> None:
        dog = self.dog
        assert dog is not None, "closed"
        for _ in range(n):
            self.seq += 1
            h = _ping_once(self.mode, self.seq, self.pub, self.sub, self.counters, dog)
            if h is None:
                self.lost += 1
            else:
                self.hops.append(h)

    def close(self) -> None:
        if self.dog is not None:
            self.dog.close()
            self.dog = None
        stop_process(self.proc)
        self.session.close()


BLOCK = 50      # pings per mode before the next mode's turn


def main(argv: list[str] | None = None) -> int:
    ap = bench_args(__doc__.splitlines()[0], runs=5)
    ap.add_argument("--pings", type=int, default=2000, help="timed ping-pongs per mode and run (default 2000)")
    ap.add_argument("--echo", metavar="ENDPOINT", help=argparse.SUPPRESS)
    ap.add_argument("--mode", choices=tuple(SHAPE), default="raw", help=argparse.SUPPRESS)
    ap.add_argument("--profile", action="store_true",
                    help="also the modes adding one of the project's differences each to raw (options, latest, codec)")
    ap.add_argument("--certs", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--secure", action="store_true", help="also the project path over mutual TLS + ACL (figure 2s)")
    args = ap.parse_args(argv)
    if args.echo:
        return echo(args.echo, args.mode, args.certs)
    with tempfile.TemporaryDirectory(prefix="bench-hop-") as tmp:
        certs = Path(tmp)
        if args.secure:
            make_certs(certs, ("edge", "controller"))
        modes = (*MODES, *(PROFILE_MODES if args.profile else ()), *(("tls",) if args.secure else ()))
        return _measure(args, modes, certs)


def _measure(args: argparse.Namespace, modes: tuple[str, ...], certs: Path) -> int:
    pings = 50 if args.quick else args.pings
    runs = 1 if args.quick else args.runs
    pooled: dict[str, list[int]] = {m: [] for m in modes}
    medians: dict[str, list[float]] = {m: [] for m in modes}
    lost: dict[str, int] = {m: 0 for m in modes}
    for i in range(runs):
        batches: list[Batch] = []
        try:
            for mode in modes:
                batches.append(Batch(mode, certs))
            for done in range(0, pings, BLOCK):      # the modes in turn, BLOCK pings each: the same load for all
                for b in batches:
                    b.ping(min(BLOCK, pings - done))
        finally:
            for b in batches:
                b.close()
        for b in batches:
            pooled[b.mode] += b.hops
            medians[b.mode].append(pct(b.hops, 50) / 1e3)
            lost[b.mode] += b.lost
            print(f"run {i + 1}/{runs} {b.mode:8s}: median {medians[b.mode][-1]:.1f} us  p99 "
                  f"{pct(b.hops, 99) / 1e3:.1f} us  lost {b.lost}", flush=True)
    details = [{"mode": m, "hops": len(pooled[m]), "lost": lost[m], "median_us": pct(pooled[m], 50) / 1e3,
                "p99_us": pct(pooled[m], 99) / 1e3, "min_us": min(pooled[m], default=0) / 1e3,
                "max_us": max(pooled[m], default=0) / 1e3,
                "ratio_to_raw": pct([x / r for x, r in zip(medians[m], medians["raw"], strict=True)], 50)} for m in modes]
    base = pct(medians["raw"], 50)
    rec = record("2", "Zenoh hop latency, project path vs raw zenoh-python", runs=runs,
                 metric=f"one-way hop (round trip / 2) on loopback, median per run of {pings} pings; p99 pooled",
                 unit="us", per_run=medians["project"], p99=pct(pooled["project"], 99) / 1e3, baseline=base,
                 baseline_label="raw zenoh-python ping-pong, same payload sizes (median of run medians)",
                 goal="ratio <= 1.3", details=details,
                 notes="`blocking` row = project payloads and publishers with a FIFO receive at the echo: the gap "
                       "between `project` and `blocking` is the newest-only hand-off (`LatestSubscriber`); "
                       "`ratio_to_raw` = median of the per-run ratios (`--profile` rows: one difference each).")
    ratios = [p / r for p, r in zip(medians["project"], medians["raw"], strict=True)]
    rec["ratio"] = pct(ratios, 50)   # per-run ratios: both modes of a run share the machine's state
    rec["notes"] += f" Ratio = median of the per-run ratios project/raw: {', '.join(f'{x:.2f}' for x in ratios)}."
    rec["goal_met"] = rec["ratio"] <= 1.3
    records = [rec]
    if "tls" in modes:
        tls = [t / p for t, p in zip(medians["tls"], medians["project"], strict=True)]
        sec = record("2s", "Zenoh hop latency over the secure profile (mTLS + ACL) vs the same path on TCP", runs=runs,
                     metric=f"as figure 2, `tls` mode: median per run of {pings} pings; p99 pooled", unit="us",
                     per_run=medians["tls"], p99=pct(pooled["tls"], 99) / 1e3, baseline=pct(medians["project"], 50),
                     baseline_label="`project` mode on plain TCP (median of run medians)", details=details,
                     notes="Ratio = median of the per-run ratios tls/project: " + ", ".join(f"{x:.2f}" for x in tls))
        sec["ratio"] = pct(tls, 50)
        records.append(sec)
    emit(records, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
