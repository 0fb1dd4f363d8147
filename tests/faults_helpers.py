"""Helpers for the fault-injection tests: an in-process rig (plant + edge + recorder on a private `virtual` CAN bus,
Zenoh listening on a free loopback port), controller child processes, condition waits and a link outage.

Nothing here sleeps for synchronisation: `wait_for` re-checks a condition every few ms until a deadline.
"""
from __future__ import annotations

import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from paper_scheme import paper

from sea_hil.config.comms import LinkDirectionConfig
from sea_hil.config.loader import config_to_toml, load_config
from sea_hil.config.root import SeaHilConfig
from sea_hil.controller.edge import EdgeNode
from sea_hil.plant_emulator.node import PlantNode
from sea_hil.protocol.can_frames import DriverState
from sea_hil.protocol.canbus import open_bus
from sea_hil.protocol.link import LinkCounters, LinkEmulator
from sea_hil.protocol.zsession import free_tcp_port
from sea_hil.recorder.node import RecorderNode
from sea_hil.recorder.writer import SessionRecorder
from sea_hil.runtime.processes import end_process as _end_process
from sea_hil.session.builder import SessionBuilder

REPO = Path(__file__).resolve().parents[1]
NODE = 1
STOP_TIMEOUT_S = 10.0


def wait_for(cond: Callable[[], bool], timeout_s: float, poll_s: float = 0.002) -> int | None:
    """Monotonic ns at which `cond()` first held, or None if it did not within `timeout_s`."""
    deadline = time.monotonic_ns() + int(timeout_s * 1e9)
    tick = threading.Event()
    while True:
        if cond():
            return time.monotonic_ns()
        if time.monotonic_ns() > deadline:
            return None
        tick.wait(poll_s)


def end_process(proc: subprocess.Popen[bytes] | subprocess.Popen[str]) -> None:
    """`sea_hil.runtime.processes.end_process` with this module's stop timeout; safe to call twice."""
    _end_process(proc, STOP_TIMEOUT_S)


def sea_hil_cmd(*args: str) -> list[str]:
    return [sys.executable, "-m", "sea_hil.cli", *args]


class OutageLink(LinkEmulator):
    """A `LinkEmulator` that additionally drops everything submitted in [start_ns, end_ns) (sample time): a total
    link outage. Outage drops are reported in `dropped_outage` and, for the node's stats, as random drops."""

    def __init__(self, cfg: LinkDirectionConfig, seed: str, start_ns: int, end_ns: int) -> None:
        super().__init__(cfg, seed)
        self.start_ns, self.end_ns = start_ns, end_ns
        self.dropped_outage = 0

    def submit(self, t_ns: int, payload_len_bytes: int) -> int | None:
        if self.start_ns <= t_ns < self.end_ns:
            self.dropped_outage += 1
            return None
        return super().submit(t_ns, payload_len_bytes)

    def counters(self) -> LinkCounters:
        c = super().counters()
        return LinkCounters(c.submitted + self.dropped_outage, c.dropped_random + self.dropped_outage,
                            c.dropped_burst, c.dropped_queue, c.delivered, c.mean_added_delay_s)


@dataclass
class Rig:
    """Plant + edge + recorder threads in this process (composed by the `SessionBuilder`); the controller is a child
    process over Zenoh."""
    cfg: SeaHilConfig
    cfg_path: Path
    endpoint: str
    plant: PlantNode
    edge: EdgeNode
    recorder: RecorderNode
    mcap: Path
    _builder: SessionBuilder

    @classmethod
    def start(cls, tmp: Path, overrides: dict | None = None) -> Rig:
        # the paper's scheme (a state every sample: the outage and kill counts of tests/test_faults.py are its)
        cfg = load_config(None, paper({"can": {"interface": f"virtual:faults-{uuid.uuid4().hex[:8]}"},
                                       **(overrides or {})}))
        cfg_path = tmp / "config.toml"
        cfg_path.write_text(config_to_toml(cfg), encoding="utf-8")
        endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
        b = SessionBuilder(cfg)
        try:
            session = b.zenoh(listen=[endpoint])
            buses = [b.bus() for _ in range(3)]
            rec = SessionRecorder.from_config(tmp / "session.mcap", cfg.record)
            b.callback(rec.close)   # idempotent; normally closed with the final counters below
            rec.write_session_header(cfg, seed=cfg.link.seed, argv=["test_faults"])
            recorder = b.recorder(rec, session, buses[2])
            plant = b.plant(buses[0], (NODE,))
            edge = b.edge(buses[1], session, NODE)
            b.callback(lambda: rec.close(final_stats=recorder.counters()))   # after plant, edge, recorder stop
            b.callback(lambda: [n.close() for n in (plant, edge, recorder)])
        except BaseException:
            b.close()
            raise
        rig = cls(cfg, cfg_path, endpoint, plant, edge, recorder, tmp / "session.mcap", b)
        for node in (recorder, plant, edge):
            node.start()
        return rig

    def driver_state(self) -> DriverState:
        return self.plant.drivers[NODE].state

    def controller(self, cycles: int = 50) -> subprocess.Popen[bytes]:
        """Start a remote ET controller child process connected to this rig."""
        return subprocess.Popen(sea_hil_cmd("controller", "--config", str(self.cfg_path), "--connect", self.endpoint,
                                            "--controller", "et", "--cycles", str(cycles)),
                                cwd=REPO, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                stderr=subprocess.PIPE)

    def close(self) -> None:
        """Stop every node, finalise the MCAP file, close Zenoh and the buses (idempotent)."""
        self._builder.close()


# ---- edge kill/restart across processes: ipc CAN, inside a private network namespace ----------------------------
def run_edge_kill_in_netns(timeout_s: float = 120.0) -> dict[str, float]:
    """Run `python tests/faults_helpers.py edge-kill ipc:NAME` (a fresh channel: other runs share the filesystem)
    under `unshare --net --pid` (lo up) and return its JSON report."""
    import json
    import shlex
    import uuid
    spec = f"ipc:edge-kill-{uuid.uuid4().hex[:12]}"
    script = (f"ip link set lo up && exec {shlex.quote(sys.executable)} "
              f"{shlex.quote(str(Path(__file__).resolve()))} edge-kill {spec}")
    # its own PID namespace too: if the helper is killed (the timeout) its plant, controller and edge die with it
    res = subprocess.run(["unshare", "--net", "--pid", "--fork", "--kill-child", "--mount-proc", "sh", "-c", script],
                         capture_output=True, text=True, cwd=REPO, timeout=timeout_s, check=False,
                         stdin=subprocess.DEVNULL)
    assert res.returncode == 0, res.stdout + res.stderr
    return json.loads(res.stdout.strip().splitlines()[-1])


def _edge_kill_main(spec: str) -> dict[str, float]:
    """Plant, controller and edge as separate `sea-hil` processes; SIGKILL the edge, then restart it. Times from
    the kill to the driver's FAULT heartbeat and from the restart to its RUNNING heartbeat."""
    import signal

    from sea_hil.errors import MalformedFrame
    from sea_hil.protocol.can_codec import SeaCodec
    from sea_hil.protocol.can_frames import Heartbeat
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    codec, bus = SeaCodec([NODE]), open_bus(spec)
    state = {"s": DriverState.INIT, "flags": ""}

    def pump_until(target: DriverState, timeout: float) -> int | None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            msg = bus.recv(timeout=0.05)
            if msg is None:
                continue
            try:
                f = codec.decode(msg)
            except MalformedFrame:
                continue
            if isinstance(f, Heartbeat):
                state["s"], state["flags"] = f.state, repr(f.flags)
                if f.state is target:
                    return time.monotonic_ns()
        return None

    def edge() -> subprocess.Popen[bytes]:
        return subprocess.Popen(sea_hil_cmd("edge", "--can", spec, "--connect", endpoint), cwd=REPO,
                                stdin=subprocess.DEVNULL)
    procs = [subprocess.Popen(sea_hil_cmd("plant", "--can", spec, "--node", str(NODE)), cwd=REPO,
                              stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL),
             subprocess.Popen(sea_hil_cmd("controller", "--listen", endpoint, "--cycles", "50"), cwd=REPO,
                              stdin=subprocess.DEVNULL)]
    try:
        procs.append(edge())
        if pump_until(DriverState.RUNNING, 60) is None:
            raise SystemExit(f"session never RUNNING (last {state['s'].name})")
        procs[-1].send_signal(signal.SIGKILL)
        procs[-1].wait(timeout=STOP_TIMEOUT_S)
        killed = time.monotonic_ns()
        safe = pump_until(DriverState.FAULT, 10)
        if safe is None:
            raise SystemExit(f"no FAULT after the edge kill (last {state['s'].name})")
        restarted = time.monotonic_ns()
        procs.append(edge())
        running = pump_until(DriverState.RUNNING, 60)
        if running is None:
            raise SystemExit(f"no RUNNING after the edge restart (last {state['s'].name}, flags {state['flags']})")
        return {"safe_ms": (safe - killed) / 1e6, "resumed_ms": (running - restarted) / 1e6}
    finally:
        for proc in reversed(procs):
            end_process(proc)
        bus.shutdown()


if __name__ == "__main__":
    import json
    if sys.argv[1:2] != ["edge-kill"] or len(sys.argv) != 3:
        raise SystemExit("usage: faults_helpers.py edge-kill CAN_SPEC")
    print(json.dumps(_edge_kill_main(sys.argv[2])))
