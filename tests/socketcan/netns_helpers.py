"""Network-namespace helpers of the SocketCAN/netem tests (plain functions; the fixtures live in conftest.py)."""
from __future__ import annotations

import subprocess
from collections.abc import Callable

from socketcan_helpers import PROCESS_TIMEOUT_S

# TEST-NET-1 (RFC 5737): exist only inside a test's own namespaces
SERVER_ADDR = "192.0.2.1"
CLIENT_ADDR = "192.0.2.2"


def run(*args: str, timeout_s: float = PROCESS_TIMEOUT_S) -> None:
    """Run a command (e.g. ``ip``/``tc``), raising AssertionError with its stderr on failure."""
    result = subprocess.run(list(args), stdin=subprocess.DEVNULL, capture_output=True, text=True,
                            timeout=timeout_s, check=False)
    if result.returncode != 0:
        raise AssertionError(f"{' '.join(args)} failed ({result.returncode}): {result.stderr.strip()}")


def veth_pair(netns: Callable[[str], str]) -> tuple[str, str]:
    """Two fresh namespaces from the `netns` factory joined by veth ``v0`` (SERVER_ADDR) / ``v1`` (CLIENT_ADDR),
    addresses set and links (and lo) up -> (server namespace, client namespace)."""
    server_ns, client_ns = netns("seahil-srv"), netns("seahil-cli")
    run("ip", "link", "add", "v0", "netns", server_ns, "type", "veth", "peer", "name", "v1", "netns", client_ns)
    for ns, dev, addr in ((server_ns, "v0", SERVER_ADDR), (client_ns, "v1", CLIENT_ADDR)):
        run("ip", "-n", ns, "addr", "add", f"{addr}/24", "dev", dev)
        run("ip", "-n", ns, "link", "set", dev, "up")
        run("ip", "-n", ns, "link", "set", "lo", "up")
    return server_ns, client_ns
