"""A member of an `ipc` CAN bus in a process of its own, for tests/test_ipc_bus.py.

Usage: python tests/ipc/member.py DIRECTORY CHANNEL send COUNT SENDER_ID [SNDBUF_BYTES]
       python tests/ipc/member.py DIRECTORY CHANNEL idle
`send`: COUNT frames, data = SENDER_ID (1 byte) + index (4 bytes, little endian), id 0x100 + SENDER_ID, as fast as
the bus takes them, reading (and discarding) what the other members send, as every member must (one that never
reads is a stuck member to the others); then one JSON line: the bus's counters. `idle`: joins, prints "joined" and
waits on stdin (the dead-member test kills it).
"""
from __future__ import annotations

import json
import sys

import can

from sea_hil.protocol.ipc_bus import SNDBUF_BYTES, IpcBus


def main(argv: list[str]) -> int:
    directory, channel, mode = argv[:3]
    if mode == "idle":
        bus = IpcBus(channel, directory=directory)
        print("joined", flush=True)
        sys.stdin.read()
        bus.shutdown()
        return 0
    count, sender = int(argv[3]), int(argv[4])
    bus = IpcBus(channel, directory=directory, sndbuf_bytes=int(argv[5]) if len(argv) > 5 else SNDBUF_BYTES,
                 send_timeout_s=60.0)
    head = bytes([sender])
    for i in range(count):
        bus.send(can.Message(arbitration_id=0x100 + sender, data=head + i.to_bytes(4, "little"),
                             is_extended_id=False))
        while bus.recv(0) is not None:
            pass
    print(json.dumps({"sent": bus.frames_sent, "dropped": bus.frames_dropped, "waits": bus.send_waits,
                      "members": bus.member_count}), flush=True)
    bus.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
