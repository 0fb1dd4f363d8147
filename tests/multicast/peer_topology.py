"""The README's multi-host commands as separate processes, peer-to-peer on one host (issue 32): `sea-hil edge
--listen tcp/127.0.0.1:PORT`, `sea-hil record --connect` to it (a Zenoh client of the edge: `sea_hil.commands.record.
as_observer`), `sea-hil plant` and `sea-hil controller --connect` to it; CAN on `ipc:NAME` (the lossless one-host bus); plant, edge
and controller with `--lockstep`. No router: the edge is the only listener.

A second recorder starts late, once the controller has exited (the session is over but for the edge's final
statistics): its file must say which channels it lacks and by how much.

Usage: python tests/multicast/peer_topology.py CONFIG.toml OUT_DIR CAN_SPEC  (prints one JSON line: exit codes, each
node's stdout, the summary of the full recording, the completeness of the late one). The caller
(tests/test_compose_topology.py) runs it under ``unshare --net --pid`` with ``lo`` up. Ordering
is by events, never by sleeping: the recorder's "recording" line before the plant starts, the controller's exit
before the late recorder, its "recording" line before the edge is stopped, the edge's exit (it publishes its final
statistics first) before the recorders are stopped. Every process is ended, also on failure.
"""
from __future__ import annotations

import json
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

from sea_hil.protocol.zsession import free_tcp_port
from sea_hil.recorder.reader import read_session
from sea_hil.report.completeness import completeness_block
from sea_hil.report.session_summary import session_summary
from sea_hil.runtime.processes import end_process

REPO = Path(__file__).resolve().parents[2]

SESSION_TIMEOUT_S = 240.0
STEP_TIMEOUT_S = 60.0
READY = "sea-hil record: recording"


def readme_commands(config: Path, out: Path, port: int, can: str) -> dict[str, list[str]]:
    """The README's (docs/topologies.md) peer-to-peer commands, one host."""
    ep, cfg = f"tcp/127.0.0.1:{port}", ["--config", str(config)]
    return {
        "edge": ["edge", "--can", can, "--node", "1", "--listen", ep, *cfg, "--lockstep", "--json"],
        "recorder": ["record", "--out", str(out / "session.mcap"), "--can", can, "--connect", ep, *cfg],
        "plant": ["plant", "--can", can, "--node", "1", *cfg, "--lockstep"],
        "controller": ["controller", "--controller", "et", "--cycles", "1", "--connect", ep, *cfg, "--lockstep",
                       "--json"],
        "late": ["record", "--out", str(out / "late.mcap"), "--connect", ep, *cfg, "--json"],
    }


class Node:
    """One `sea-hil` process; its stderr is copied to ours and watched for `READY`, its stdout kept."""

    def __init__(self, args: list[str]) -> None:
        self.proc = subprocess.Popen([sys.executable, "-m", "sea_hil.cli", *args], cwd=REPO, stdin=subprocess.DEVNULL,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.ready = threading.Event()
        self.stdout = ""
        self._threads = [threading.Thread(target=self._err, daemon=True),
                         threading.Thread(target=self._out, daemon=True)]
        for t in self._threads:
            t.start()

    def _err(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            sys.stderr.write(line)
            if line.startswith(READY):
                self.ready.set()

    def _out(self) -> None:
        assert self.proc.stdout is not None
        self.stdout = self.proc.stdout.read()

    def wait_ready(self, what: str) -> None:
        deadline = time.monotonic() + STEP_TIMEOUT_S
        while not self.ready.wait(0.2):
            if self.proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"{what} never got ready (exit {self.proc.poll()})")

    def end(self, timeout_s: float = STEP_TIMEOUT_S) -> int:
        code = end_process(self.proc, timeout_s=timeout_s)
        for t in self._threads:
            t.join(timeout=STEP_TIMEOUT_S)
        return code


def wait_listening(port: int, proc: subprocess.Popen[str]) -> None:
    """Until the edge accepts TCP connections on `port` (or has died / STEP_TIMEOUT_S passed)."""
    deadline = time.monotonic() + STEP_TIMEOUT_S
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=1.0):
                return
        except OSError:
            time.sleep(0.05)    # poll a condition (the port), not a delay standing in for it
    raise RuntimeError(f"the edge never listened on {port} (exit {proc.poll()})")


def start_session(cmds: dict[str, list[str]], port: int, nodes: dict[str, Node]) -> None:
    """The README's order, by events: the edge listening, the recorder subscribed, then plant and controller (each
    added to `nodes` as it starts, so the caller's `finally` ends whatever started)."""
    nodes["edge"] = Node(cmds["edge"])
    wait_listening(port, nodes["edge"].proc)
    nodes["recorder"] = Node(cmds["recorder"])
    nodes["recorder"].wait_ready("the recorder")
    for name in ("plant", "controller"):
        nodes[name] = Node(cmds[name])


def run(config: Path, out: Path, can: str) -> dict[str, object]:
    port = free_tcp_port()
    cmds = readme_commands(config, out, port, can)
    nodes: dict[str, Node] = {}
    codes: dict[str, int] = {}
    try:
        start_session(cmds, port, nodes)
        codes["controller"] = nodes["controller"].proc.wait(timeout=SESSION_TIMEOUT_S)
        nodes["late"] = Node(cmds["late"])
        nodes["late"].wait_ready("the late recorder")
        codes["edge"] = nodes["edge"].end()          # SIGTERM: final statistics published, then exit
        for name in ("plant", "recorder", "late", "controller"):
            codes[name] = nodes[name].end()
    finally:
        for node in nodes.values():
            node.end(5.0)
    data = read_session(out / "session.mcap")
    summary = session_summary(data, "et")
    summary.update(lockstep=True, inner="edge", completeness=completeness_block(data))
    return {"codes": codes, "stdout": {name: node.stdout for name, node in nodes.items()}, "summary": summary,
            "late": completeness_block(read_session(out / "late.mcap"))}


if __name__ == "__main__":
    print(json.dumps(run(Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3])))
