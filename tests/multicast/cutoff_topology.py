"""The README's peer-to-peer topology (tests/multicast/peer_topology.py) with its recorder cut off mid-session
(issue 32): the recorder (CAN tap included) is SIGKILLed once its file holds a few of the session's states while the
controller is still running; the session goes on to its end without it, and the edge and the controller end with
their own `--json` results. What the torn file holds is then checked against those results (`sea-hil report
--node-summary`, by the caller).

Usage: python tests/multicast/cutoff_topology.py CONFIG.toml OUT_DIR CAN_SPEC  (prints one JSON line: exit codes, each
node's stdout, whether the controller was still running when the recorder was killed). The caller
(tests/test_compose_topology.py) runs it under ``unshare --net --pid`` with ``lo`` up. Ordering
is by events, never by sleeping: the recorder's "recording" line before the plant starts; the kill once the file
(read back as a recovered file is) holds `CUT_AFTER_STATES` states; the controller's exit before the edge is
stopped. Every process is ended, also on failure.
"""
from __future__ import annotations

import json
import signal
import sys
import time
from pathlib import Path

from peer_topology import SESSION_TIMEOUT_S, STEP_TIMEOUT_S, Node, readme_commands, start_session

from sea_hil.protocol.zsession import free_tcp_port
from sea_hil.recorder.reader import read_session

CUT_AFTER_STATES = 60     # the lead-in's 25 states and 35 of the cycle's 100: mid-cycle, well before its end
POLL_S = 0.05             # the file is polled (a condition), not waited on for a fixed time


def recorded_states(path: Path) -> int:
    """States in the file being written, read as a recovered file (complete chunks only); 0 before it parses."""
    try:
        return len(read_session(path).messages.get("/zenoh/state", []))
    except OSError:    # not created yet (a file with no complete chunk yet reads as empty)
        return 0


def wait_recorded(path: Path, states: int, controller: Node) -> None:
    """Until the file holds `states` states (or the controller has ended / STEP_TIMEOUT_S passed: then raise)."""
    deadline = time.monotonic() + STEP_TIMEOUT_S
    while recorded_states(path) < states:
        if controller.proc.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"the recording never held {states} states while the controller ran "
                               f"(controller exit {controller.proc.poll()})")
        time.sleep(POLL_S)


def run(config: Path, out: Path, can: str) -> dict[str, object]:
    port = free_tcp_port()
    cmds = readme_commands(config, out, port, can)
    nodes: dict[str, Node] = {}
    codes: dict[str, int] = {}
    try:
        start_session(cmds, port, nodes)
        wait_recorded(out / "session.mcap", CUT_AFTER_STATES, nodes["controller"])
        nodes["recorder"].proc.send_signal(signal.SIGKILL)
        codes["recorder"] = nodes["recorder"].end()
        cut_mid_session = nodes["controller"].proc.poll() is None
        codes["controller"] = nodes["controller"].proc.wait(timeout=SESSION_TIMEOUT_S)
        codes["edge"] = nodes["edge"].end()          # SIGTERM: final statistics published, its result printed
        codes["plant"] = nodes["plant"].end()
    finally:
        for node in nodes.values():
            node.end(5.0)
    return {"codes": codes, "stdout": {name: node.stdout for name, node in nodes.items()},
            "cut_mid_session": cut_mid_session}


if __name__ == "__main__":
    print(json.dumps(run(Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3])))
