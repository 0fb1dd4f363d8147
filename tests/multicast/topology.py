"""The docker-compose topology as separate processes: a Zenoh router (a zenoh-python session in router mode standing
for zenohd) and the compose file's `sea-hil plant | edge | controller | record` services, each a process of its own
running the command docker-compose.yml gives it, with only the host-specific parts substituted: the router's
endpoint (a free loopback port), the CAN bus (an `ipc:NAME` bus for vcan0: the processes of one host), the config (/config/session.toml)
and the output (/runs); plant, edge and controller get `--lockstep`. So the Zenoh nodes run in client mode
(session.toml) and know only the router. One lockstep session; writes OUT/summary.json from the recording.

Usage: python tests/multicast/topology.py CONFIG.toml OUT_DIR CAN_SPEC  (prints one JSON line: exit codes, summary path)
The caller (tests/test_compose_topology.py) runs it under ``unshare --net --pid`` with ``lo`` up, so the router's
port never leaves the namespace and every node dies with the script; the ipc channel is the caller's, unique. Ordering is by events, never by sleeping: the nodes start
once the router sees the recorder's subscription; the edge is stopped when the controller has exited, and the
recorder once the router has forwarded the edge's final statistics. Every process is ended, also on failure.
"""
from __future__ import annotations

import json
import subprocess
import sys
import threading
from pathlib import Path

import yaml

from sea_hil.config.loader import load_config
from sea_hil.protocol.keys import Keys
from sea_hil.protocol.zsession import free_tcp_port, make_config, open_session
from sea_hil.recorder.reader import read_session
from sea_hil.report.completeness import completeness_block
from sea_hil.report.session_summary import session_summary
from sea_hil.report.summary import write_summary
from sea_hil.runtime.processes import end_process

REPO = Path(__file__).resolve().parents[2]

SESSION_TIMEOUT_S = 240.0
STEP_TIMEOUT_S = 60.0


def compose_commands(config: Path, out: Path, endpoint: str, can: str) -> dict[str, list[str]]:
    """Each sea-hil service's docker-compose.yml command with the host-specific parts substituted (module doc)."""
    services = yaml.safe_load((REPO / "docker-compose.yml").read_text())["services"]
    subst = {"socketcan:vcan0": can, "/config/session.toml": str(config),
             "/runs/session.mcap": str(out / "session.mcap")}
    cmds = {}
    for name in ("recorder", "plant", "edge", "controller"):
        cmd = services[name]["command"]
        assert cmd[0] == "sea-hil", name
        args = [endpoint if a.startswith("tcp/") else subst.get(a, a) for a in cmd[1:]]
        cmds[name] = args if name == "recorder" else [*args, "--lockstep"]
    return cmds


def _node(args: list[str]) -> subprocess.Popen[bytes]:
    return subprocess.Popen([sys.executable, "-m", "sea_hil.cli", *args], cwd=REPO, stdin=subprocess.DEVNULL)


def _wait(event: threading.Event, what: str) -> None:
    if not event.wait(STEP_TIMEOUT_S):
        raise TimeoutError(f"timed out waiting for {what}")


def run(config: Path, out: Path, can: str) -> dict[str, object]:
    cfg = load_config(config)
    keys = Keys.from_config(cfg.zenoh)
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    cmds = compose_commands(config, out, endpoint, can)
    router = open_session(make_config(mode="router", listen=[endpoint]))
    procs: dict[str, subprocess.Popen[bytes]] = {}
    recorder_ready, edge_final = threading.Event(), threading.Event()
    probe = router.declare_publisher(keys.state)     # matches once the recorder has subscribed to <prefix>/**
    listener = probe.declare_matching_listener(lambda status: status.matching and recorder_ready.set())
    stats = router.declare_subscriber(keys.stats, lambda s: '"final": true' in s.payload.to_string()
                                      and '"feedback_samples"' in s.payload.to_string() and edge_final.set())
    codes: dict[str, int] = {}
    try:
        procs["recorder"] = _node(cmds["recorder"])
        if probe.matching_status.matching:
            recorder_ready.set()
        _wait(recorder_ready, "the recorder's subscription")
        for name in ("plant", "edge", "controller"):
            procs[name] = _node(cmds[name])
        codes["controller"] = procs["controller"].wait(timeout=SESSION_TIMEOUT_S)
        # SIGTERM: the edge publishes its final statistics, then exits. Each node gets STEP_TIMEOUT_S for it (not
        # end_process's 5 s): in a fresh-clone CI run beside another xdist worker's numba compiles, the edge was
        # SIGKILLed at 5 s before it had published them and the wait below timed out
        codes["edge"] = end_process(procs["edge"], timeout_s=STEP_TIMEOUT_S)
        _wait(edge_final, f"the edge's final statistics (edge exit {codes['edge']})")
        codes["plant"] = end_process(procs["plant"], timeout_s=STEP_TIMEOUT_S)
        codes["recorder"] = end_process(procs["recorder"], timeout_s=STEP_TIMEOUT_S)
    finally:
        for proc in procs.values():
            end_process(proc)
        listener.undeclare()
        stats.undeclare()
        probe.undeclare()
        router.close()
    data = read_session(out / "session.mcap")
    summary = session_summary(data, "et")
    summary.update(lockstep=True, inner="edge", completeness=completeness_block(data))
    write_summary(out / "summary.json", summary)
    return {"codes": codes, "summary": str(out / "summary.json")}


if __name__ == "__main__":
    print(json.dumps(run(Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3])))
