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


def test_sea_hil_router_routes_between_two_clients() -> None:
    """`sea-hil router` (zenoh-python's router mode; docs/topologies.md): two clients of it reach each other."""
    import threading

    from sea_hil.protocol.zsession import make_config, open_session
    from sea_hil.runtime.processes import end_process
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    proc = subprocess.Popen([sys.executable, "-m", "sea_hil.cli", "router", "--listen", ep], stdin=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stderr is not None and proc.stderr.readline().startswith("sea-hil router: listening on")
        got = threading.Event()
        a = open_session(make_config(mode="client", connect=[ep]))
        b = open_session(make_config(mode="client", connect=[ep]))
        try:
            sub = a.declare_subscriber("sea/test/**", lambda s: got.set())
            pub = b.declare_publisher("sea/test/x")
            for _ in range(100):     # until the subscription has reached the router: each put is a new chance
                pub.put(b"x")
                if got.wait(0.1):
                    break
            assert got.is_set()
            sub.undeclare()
        finally:
            b.close()
            a.close()
    finally:
        assert end_process(proc, timeout_s=30) == 0


def test_a_recorder_that_only_connects_joins_as_a_client() -> None:
    """Two zenoh 1.10 peers forward each other only their own publications (docs/topologies.md): a recorder on the
    edge's endpoint is its client, unless it listens or --mode says otherwise."""
    from sea_hil.commands.record import as_observer
    from sea_hil.config.loader import load_config
    connect = {"zenoh": {"connect": ["tcp/127.0.0.1:7447"]}}
    assert as_observer(load_config(overrides=connect), None).zenoh.mode == "client"
    assert as_observer(load_config(overrides=connect), "peer").zenoh.mode == "peer"
    both = {"zenoh": {"connect": ["tcp/127.0.0.1:7447"], "listen": ["tcp/127.0.0.1:7448"]}}
    assert as_observer(load_config(overrides=both), None).zenoh.mode == "peer"
    assert as_observer(load_config(), None).zenoh.mode == "peer"
