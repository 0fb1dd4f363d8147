"""Issue 32: a node run on its own ends with its result. `sea-hil controller` that never meets an edge gives up
after --timeout: exit 3 and its table (stopped, nothing handled), or with --json its summary, which validates
against the node schema. The four-process topology (tests/test_compose_topology.py) checks the others'."""
from __future__ import annotations

import json
import subprocess
import sys

import jsonschema

from sea_hil.protocol.zsession import free_tcp_port
from sea_hil.report.node_summary import NODE_SUMMARY_SCHEMA


def _controller(*extra: str) -> subprocess.CompletedProcess[str]:
    cmd = [sys.executable, "-m", "sea_hil.cli", "controller", "--timeout", "0.5", "--lockstep",
           "--listen", f"tcp/127.0.0.1:{free_tcp_port()}", *extra]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False, stdin=subprocess.DEVNULL)


def test_a_controller_alone_prints_its_table_and_json() -> None:
    table = _controller()
    assert table.returncode == 3, table.stderr
    assert "sea-hil controller" in table.stdout and "controller, stopped" in table.stdout
    assert "states handled / setpoints sent" in table.stdout and "0 / 0" in table.stdout
    as_json = _controller("--json")
    assert as_json.returncode == 3, as_json.stderr
    summary = json.loads(as_json.stdout)
    jsonschema.validate(summary, NODE_SUMMARY_SCHEMA)
    assert summary["node"] == "controller" and not summary["finished"]
    assert summary["counters"]["states_handled"] == 0 and "latency_us" not in summary
