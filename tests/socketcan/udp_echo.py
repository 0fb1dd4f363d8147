"""UDP echo server and ping client, run as subprocesses inside network namespaces by test_netem.py.

    python udp_echo.py serve ADDR COUNT        # prints the bound port, echoes COUNT datagrams, exits
    python udp_echo.py ping ADDR PORT COUNT    # prints one JSON list of round-trip times in ns
"""
from __future__ import annotations

import json
import socket
import sys
import time

RECV_TIMEOUT_S = 5.0


def serve(addr: str, count: int) -> None:
    """Bind an ephemeral UDP port on ``addr``, announce it on stdout, echo ``count`` datagrams."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind((addr, 0))
        sock.settimeout(RECV_TIMEOUT_S * 4)
        print(sock.getsockname()[1], flush=True)
        for _ in range(count):
            data, peer = sock.recvfrom(2048)
            sock.sendto(data, peer)


def ping(addr: str, port: int, count: int) -> list[int]:
    """Send ``count`` sequenced datagrams one at a time; return each round-trip time in ns."""
    rtts_ns = []
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.settimeout(RECV_TIMEOUT_S)
        for seq in range(count):
            payload = seq.to_bytes(4, "big")
            t0_ns = time.monotonic_ns()
            sock.sendto(payload, (addr, port))
            while sock.recv(2048) != payload:  # drop anything stale
                pass
            rtts_ns.append(time.monotonic_ns() - t0_ns)
    return rtts_ns


def main(argv: list[str]) -> int:
    """Command-line entry point."""
    if len(argv) == 3 and argv[0] == "serve":
        serve(argv[1], int(argv[2]))
    elif len(argv) == 4 and argv[0] == "ping":
        print(json.dumps(ping(argv[1], int(argv[2]), int(argv[3]))), flush=True)
    else:
        print(__doc__, file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
