"""netem smoke test: two network namespaces joined by a veth pair, 20 ms netem delay on each end.

A UDP ping-pong between the namespaces must show RTT >= 40 ms with netem and < 40 ms without. Needs root,
``ip netns`` and the sch_netem module (skipped otherwise); the UML guest of scripts/with-vcan has all three.
Addresses are from TEST-NET-1 (192.0.2.0/24, RFC 5737) and exist only inside the test's own namespaces.
"""
from __future__ import annotations

import json
import select
import subprocess
import sys
from pathlib import Path

from netns_helpers import SERVER_ADDR, run
from socketcan_helpers import PROCESS_TIMEOUT_S

UDP_ECHO = Path(__file__).resolve().parent / "udp_echo.py"
DELAY_MS = 20
NS_PER_MS = 1_000_000


def read_line(proc: subprocess.Popen[str], timeout_s: float) -> str:
    """First stdout line of ``proc``, waiting at most ``timeout_s``."""
    assert proc.stdout is not None
    ready, _, _ = select.select([proc.stdout], [], [], timeout_s)
    if not ready:
        raise AssertionError(f"no output from {proc.args} within {timeout_s} s")
    return proc.stdout.readline().strip()


def measure_rtts_ns(server_ns: str, client_ns: str, count: int) -> list[int]:
    """UDP round-trip times from ``client_ns`` to an echo server in ``server_ns``."""
    server = subprocess.Popen(["ip", "netns", "exec", server_ns, sys.executable, str(UDP_ECHO), "serve",
                               SERVER_ADDR, str(count)], stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True)
    try:
        port = read_line(server, PROCESS_TIMEOUT_S)  # printed after bind: the server is ready
        client = subprocess.run(["ip", "netns", "exec", client_ns, sys.executable, str(UDP_ECHO), "ping",
                                 SERVER_ADDR, port, str(count)], stdin=subprocess.DEVNULL, capture_output=True,
                                text=True, timeout=PROCESS_TIMEOUT_S * 3, check=False)
        assert client.returncode == 0, client.stderr
        assert server.wait(timeout=PROCESS_TIMEOUT_S) == 0
        return list(json.loads(client.stdout))
    finally:
        if server.poll() is None:
            server.kill()
        server.communicate()


def test_netem_delay_adds_to_udp_round_trip(veth_namespaces: tuple[str, str]) -> None:
    server_ns, client_ns = veth_namespaces
    baseline_ns = measure_rtts_ns(server_ns, client_ns, count=3)
    for ns, dev in ((server_ns, "v0"), (client_ns, "v1")):
        run("ip", "netns", "exec", ns, "tc", "qdisc", "add", "dev", dev, "root", "netem", "delay", f"{DELAY_MS}ms")
    delayed_ns = measure_rtts_ns(server_ns, client_ns, count=5)
    assert min(baseline_ns) < 2 * DELAY_MS * NS_PER_MS, baseline_ns
    assert min(delayed_ns) >= 2 * DELAY_MS * NS_PER_MS, delayed_ns
