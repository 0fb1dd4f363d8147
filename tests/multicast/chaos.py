"""Chaos: seeded kills and restarts of the edge, the controller and the recorder in a running real-time session.

The session is the compose topology (tests/multicast/topology.py): a Zenoh router (a zenoh-python session in
router mode in a process of its own, standing for zenohd) and `sea-hil plant | edge | controller | record` as processes of their own in
client mode, CAN on `ipc:NAME` (the lossless one-host bus). This process also listens to the bus (the drive's heartbeats) and to the
edge's states through the router. A seeded RNG picks 10 faults (each kind at least three times) at random times in
a 60 s window; a fault waits until the session has recovered from the previous one. After each, asserted:
- edge or controller SIGKILLed: the drive reports FAULT (safe state: zero voltage, watchdog) within the setpoint
  timeout (2 x `trigger.max_inter_event_s`) + the drive watchdog + one heartbeat period + `MARGIN_S` of the drive's
  own time (feedback samples counted on the bus; the wall time is reported, and bounded loosely); restarted, the
  session resumes (heartbeat RUNNING again);
- recorder SIGKILLed once its file holds the newest state this process has seen: the file (read back with
  `sea_hil.recorder.reader`) holds every state of the edge's stream from its first recorded one up to that state,
  without a gap; a new recorder (new file) is started and the drive never left RUNNING;
- at the end every node is ended and no process of the session is left.

Usage: python tests/multicast/chaos.py CONFIG.toml OUT_DIR CAN_SPEC SEED  (prints one JSON line: the fault log)
Run under ``unshare --net --pid --fork --kill-child --mount-proc`` (tests/test_chaos.py). Waits are on events or polls with a
deadline, never sleeps used for synchronisation.
"""
from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import threading
import time
from itertools import pairwise
from pathlib import Path

import psutil

from sea_hil.config.loader import load_config
from sea_hil.errors import MalformedFrame
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import LIMIT_FLAGS, DriverState, FeedbackAngle, Heartbeat
from sea_hil.protocol.canbus import open_bus
from sea_hil.protocol.keys import Keys
from sea_hil.protocol.payloads import PayloadCounters
from sea_hil.protocol.zsession import free_tcp_port, make_config, open_session
from sea_hil.recorder.reader import read_session
from sea_hil.runtime.processes import end_process

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "tests"))   # run as a script (tests/test_chaos.py): the tests' helpers
from faults_helpers import wait_for  # noqa: E402

NODE = 1
FAULTS, WINDOW_S = 10, 60.0
START_S = 90.0     # four interpreters + zenoh on a loaded 2-core machine
RESUME_S = 45.0    # a restarted process: interpreter, imports, zenoh, then the restart path
MARGIN_S = 0.1     # on the safe-state bound, in the drive's own time (its feedback periods)
WALL_MARGIN_S = 5.0   # the same in wall time on a loaded 2-core host (only catches a drive that never gets safe)
# the router carries every state and setpoint between the edge and the controller: on the session's real-time tier
# (`[timing]`: SCHED_FIFO as a standalone controller takes it, `node_priority`), as a zenohd on this host would be run
ROUTER = """import sys, threading
from sea_hil.config.loader import load_config
from sea_hil.protocol.zsession import make_config, open_session
from sea_hil.runtime.realtime import ThreadPolicy, node_priority
from sea_hil.config.timing import TimingConfig
s = open_session(make_config(mode="router", listen=[sys.argv[1]]))
priority = node_priority(load_config(sys.argv[2]).timing, "controller")
if priority:
    ThreadPolicy(TimingConfig(realtime_priority=priority, realtime_scope="process"), "router").apply()
print("ready", flush=True)
sys.stdin.read()   # until the orchestrator ends (SIGTERM) or closes the pipe
s.close()
"""


class Watch:
    """The drive's heartbeats (CAN thread) and the edge's newest state seq (Zenoh callback)."""

    def __init__(self, bus, session, keys: Keys) -> None:
        self.codec, self.bus = SeaCodec([NODE]), bus
        self.state, self.state_since_ns = DriverState.INIT, time.monotonic_ns()
        self.faults_seen = 0
        self.limit_faults: list[tuple[float, int]] = []   # (monotonic s, flags) of every FAULT with a soft-limit flag
        self.flags = 0
        self.samples = 0   # feedback samples the drive has sent (one FEEDBACK_ANGLE frame each): its own clock
        self.samples_at_change = 0   # `samples` when the newest state change was seen (in bus order)
        self.history: list[tuple[float, str, int]] = []   # (monotonic s, state, flags) of every state change
        self.last_seq = 0
        self._payloads = PayloadCounters()
        self._stop = threading.Event()
        self._sub = session.declare_subscriber(keys.state, self._on_state)
        self._thread = threading.Thread(target=self._can, daemon=True)
        self._thread.start()

    def _on_state(self, sample) -> None:
        p = self._payloads.try_decode(sample.payload.to_bytes())
        if p is not None:
            self.last_seq = p.seq

    def _can(self) -> None:
        while not self._stop.is_set():
            msg = self.bus.recv(timeout=0.05)
            if msg is None:
                continue
            try:
                f = self.codec.decode(msg)
            except MalformedFrame:
                continue
            self.samples += isinstance(f, FeedbackAngle)
            if isinstance(f, Heartbeat) and f.state is not self.state:
                self.state, self.state_since_ns, self.flags = f.state, time.monotonic_ns(), int(f.flags)
                self.samples_at_change = self.samples
                self.history.append((round(time.monotonic(), 2), f.state.name, int(f.flags)))
                self.faults_seen += f.state is DriverState.FAULT
                if f.state is DriverState.FAULT and f.flags & LIMIT_FLAGS:
                    self.limit_faults.append((round(time.monotonic(), 2), int(f.flags)))

    def describe(self) -> str:
        return f"drive {self.state.name}, flags {self.flags:#x}; last changes (t, state, flags) {self.history[-6:]}"

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5.0)
        self._sub.undeclare()


def _last_run(seqs: list[int]) -> list[int]:
    """The states of the newest edge stream (a restarted edge numbers its states from 1 again)."""
    starts = [i + 1 for i, (a, b) in enumerate(pairwise(seqs)) if b <= a]
    return seqs[starts[-1]:] if starts else seqs


def _logged(path: Path) -> dict[str, list[tuple[int, int]]]:
    """What the file holds now: per topic, (log time, sequence) of every message in order."""
    return {t: [(m.log_time_ns, m.sequence) for m in ms] for t, ms in read_session(path).messages.items()}


def _event_gaps(path: Path) -> int:
    """States of the newest edge stream missing from the file: gaps in `event_seq` (the edge trigger publishes only
    events: its header seq, the sample number, has gaps by design), in `seq` for the paper's every-sample stream."""
    states = [m.payload for m in read_session(path).messages.get("/zenoh/state", [])]
    seqs = _last_run([int(p.get("event_seq", p["seq"])) for p in states])
    return sum(b - a - 1 for a, b in pairwise(seqs) if b > a)


def _recorded_states(path: Path) -> list[int]:
    try:
        return [m.payload["seq"] for m in read_session(path).messages.get("/zenoh/state", [])]
    except Exception:  # noqa: BLE001 - a file being written may not parse yet
        return []


class Chaos:
    def __init__(self, config: Path, out: Path, can: str, seed: int) -> None:
        self.cfg = load_config(config)
        self.out, self.config = out, config
        self.rng = random.Random(seed)
        self.endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
        self.can = can
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        self.started: list[subprocess.Popen[bytes]] = []
        self.recordings: list[Path] = []
        c = self.cfg
        self.period_s = 1.0 / c.can.feedback_rate_hz
        # setpoint timeout + watchdog + one heartbeat period (the FAULT is seen in the next heartbeat) + margin
        self.safe_bound_s = (2 * c.trigger.max_inter_event_s + c.can.watchdog_timeout_s
                             + 1.0 / c.can.heartbeat_rate_hz + MARGIN_S)

    def cmd(self, name: str) -> list[str]:
        common = ["--config", str(self.config)]
        if name == "plant":
            return ["plant", "--can", self.can, "--node", str(NODE), *common]
        if name == "edge":
            return ["edge", "--can", self.can, "--connect", self.endpoint, *common]
        if name == "controller":
            return ["controller", "--connect", self.endpoint, "--controller", "et", "--cycles", "1000", *common]
        path = self.out / f"rec-{len(self.recordings)}.mcap"
        self.recordings.append(path)
        return ["record", "--out", str(path), "--connect", self.endpoint, *common]

    def start(self, name: str) -> None:
        p = subprocess.Popen([sys.executable, "-m", "sea_hil.cli", *self.cmd(name)], cwd=REPO,
                             stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL)
        self.procs[name] = p
        self.started.append(p)

    def plan(self) -> list[tuple[float, str]]:
        kinds = ["edge", "controller", "recorder"] * 3 + [self.rng.choice(["edge", "controller", "recorder"])]
        self.rng.shuffle(kinds)
        times = sorted(self.rng.uniform(0.0, WINDOW_S) for _ in kinds)
        return list(zip(times, kinds, strict=True))

    def running(self, w: Watch, timeout_s: float) -> bool:
        return wait_for(lambda: w.state is DriverState.RUNNING, timeout_s, poll_s=0.01) is not None

    def kill_node(self, w: Watch, name: str) -> dict[str, float]:
        # a loaded host may trip the watchdog on its own (the edge late by > 0.1 s); the edge then clears it
        assert self.running(w, RESUME_S), f"session not running before the {name} kill ({w.describe()})"
        p = self.procs[name]
        p.send_signal(signal.SIGKILL)
        p.wait(timeout=10)
        killed, samples0 = time.monotonic_ns(), w.samples
        safe = wait_for(lambda: w.state is DriverState.FAULT, self.safe_bound_s + WALL_MARGIN_S, poll_s=0.005)
        assert safe is not None, f"no safe state after the {name} kill ({w.describe()})"
        safe_s = (safe - killed) / 1e9
        # in the drive's time (its feedback periods): the bound the design guarantees; a loaded host stretches the
        # wall time when the drive misses ticks (it skips them) or the nodes are descheduled
        drive_s = (w.samples_at_change - samples0) * self.period_s
        assert drive_s <= self.safe_bound_s, f"{name} kill -> FAULT after {drive_s:.3f} s of drive time " \
            f"> {self.safe_bound_s:.3f} s (wall {safe_s:.3f} s)"
        self.start(name)
        restarted = time.monotonic_ns()
        assert self.running(w, RESUME_S), f"session did not resume after the {name} restart ({w.describe()})"
        return {"safe_s": drive_s, "safe_wall_s": safe_s, "resume_s": (time.monotonic_ns() - restarted) / 1e9}

    def kill_recorder(self, w: Watch) -> dict[str, float]:
        """SIGKILL the recorder once its file has got as far as the newest state seen here; then the file must hold every
        message it held before the kill (`_logged`: per topic, in order). States the network dropped before they
        reached the recorder (congestion on an overloaded host: Zenoh's DROP policy) were never logged; they are
        counted (`state_gaps`), not asserted."""
        path, last = self.recordings[-1], w.last_seq
        assert wait_for(lambda: max(_last_run(_recorded_states(path)), default=0) >= last, 20.0, poll_s=0.25), \
            f"the recording never reached state {last}: {path.name}"
        before = _logged(path)
        p = self.procs["recorder"]
        p.send_signal(signal.SIGKILL)
        p.wait(timeout=10)
        after = _logged(path)
        for topic, msgs in before.items():
            assert after.get(topic, [])[:len(msgs)] == msgs, f"{path.name}: {topic} lost messages logged before the kill"
        seqs = [s for _, s in after.get("/zenoh/state", [])]
        assert max(_last_run(seqs), default=0) >= last, f"{path.name}: states up to {last} (logged) missing"
        self.start("recorder")
        restarted = time.monotonic_ns()
        assert self._subscribed(), "the restarted recorder never subscribed"
        assert self.running(w, RESUME_S), f"session not running after the recorder restart ({w.describe()})"
        return {"logged": sum(map(len, before.values())), "kept": sum(map(len, after.values())),
                "recorded_states": len(seqs), "state_gaps": _event_gaps(path),
                "resume_s": (time.monotonic_ns() - restarted) / 1e9}

    def _subscribed(self) -> bool:
        return wait_for(lambda: self.probe.matching_status.matching, RESUME_S, poll_s=0.02) is not None

    def run(self) -> dict[str, object]:
        keys = Keys.from_config(self.cfg.zenoh)
        # the router is a process of its own, as zenohd is: routing must not wait for this process's GIL (a Python
        # subscriber in the router's own session stalled it while this process read the recordings, and the edge's
        # states were dropped on congestion)
        self.router = subprocess.Popen([sys.executable, "-c", ROUTER, self.endpoint, str(self.config)], cwd=REPO,
                                       stdin=subprocess.PIPE, stdout=subprocess.PIPE)
        assert self.router.stdout is not None and self.router.stdout.readline().strip() == b"ready", "no router"
        zs = open_session(make_config(mode="client", connect=[self.endpoint]))   # this process: a client
        bus = open_bus(self.can)
        self.probe = zs.declare_publisher(f"{keys.state}/probe")   # matches the recorder's <prefix>/**
        w = Watch(bus, zs, keys)
        log: list[dict[str, object]] = []
        started, start_s, span_s = time.monotonic(), None, None
        try:
            self.start("recorder")
            assert self._subscribed(), "recorder never subscribed"
            for name in ("plant", "edge", "controller"):
                self.start(name)
            assert self.running(w, START_S), f"session never RUNNING ({w.describe()})"
            t0 = time.monotonic()
            start_s = t0 - started
            print(f"chaos: RUNNING {start_s:.1f} s after the start", file=sys.stderr, flush=True)
            for at_s, kind in self.plan():
                threading.Event().wait(max(0.0, at_s - (time.monotonic() - t0)))   # the seeded fault time
                t = time.monotonic() - t0
                res = self.kill_recorder(w) if kind == "recorder" else self.kill_node(w, kind)
                log.append({"at_s": round(t, 2), "kind": kind, **{k: round(v, 3) for k, v in res.items()}})
                print(f"chaos: fault {len(log)} at {t:.1f} s: {log[-1]}", file=sys.stderr, flush=True)
            span_s = time.monotonic() - t0
        finally:
            # the producers first, the recorder last (as tests/multicast/topology.py does): its SIGTERM close then
            # finalises a file nothing is still streaming into
            codes = {n: end_process(self.procs[n]) for n in ("controller", "edge", "plant", "recorder")
                     if n in self.procs}
            for p in self.started:
                end_process(p)
            w.close()
            self.probe.undeclare()
            zs.close()
            bus.shutdown()
            end_process(self.router)
        # in its own PID namespace with its own /proc (`--mount-proc`): any other process is one left behind
        left = [pid for pid in psutil.pids() if pid != os.getpid()]
        return {"faults": log, "start_s": start_s, "span_s": span_s, "safe_bound_s": self.safe_bound_s, "codes": codes,
                "left": left, "started": len(self.started), "drive_faults_seen": w.faults_seen,
                "limit_faults": w.limit_faults}


if __name__ == "__main__":
    print(json.dumps(Chaos(Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3], int(sys.argv[4])).run()))
