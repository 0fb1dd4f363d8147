"""Drive `sea-hil plant --can udp_multicast:GROUP` from a second process; run inside a private network namespace.

Usage: python tests/multicast/probe.py GROUP  (prints one JSON line: feedback count, angles, states, plant output)
The caller (tests/test_udp_multicast.py) runs it under ``unshare --net`` after bringing ``lo`` up with a multicast
route, so the multicast group never leaves the namespace and parallel runs cannot see each other.
"""
from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

from sea_hil.errors import MalformedFrame
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import DriverState, FeedbackAngle, Heartbeat, VoltageCmd
from sea_hil.protocol.canbus import open_bus

REPO = Path(__file__).resolve().parents[2]

NODE = 1
TIMEOUT_S = 30.0
MOVED_RAD = 0.01


def drive(group: str) -> dict[str, object]:
    """Start the plant, stream hip voltage commands answering its feedback until the hip moves or time runs out."""
    codec = SeaCodec([NODE])
    bus = open_bus(f"udp_multicast:{group}")
    plant = subprocess.Popen([sys.executable, "-m", "sea_hil.cli", "plant", "--can", f"udp_multicast:{group}",
                              "--node", str(NODE), "--duration", str(TIMEOUT_S), "--watchdog", "0.5"],
                             cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    angles: list[float] = []
    states: set[str] = set()
    rejected = seq = 0
    try:
        deadline = time.monotonic() + TIMEOUT_S
        while time.monotonic() < deadline and plant.poll() is None:
            msg = bus.recv(timeout=0.05)
            if msg is None:
                continue
            try:
                frame = codec.decode(msg)
            except MalformedFrame:
                rejected += 1
                continue
            if isinstance(frame, Heartbeat):
                states.add(frame.state.name)
            elif isinstance(frame, FeedbackAngle):
                angles.append(frame.theta_rad[0])
                bus.send(codec.encode(VoltageCmd(NODE, (2.0, 0.0), seq)))  # slow: no soft limit within 1 s
                seq = (seq + 1) & 0xFF
                if abs(angles[-1] - angles[0]) > MOVED_RAD and DriverState.RUNNING.name in states:
                    break
    finally:
        plant.terminate()
        try:
            out, _ = plant.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            plant.kill()
            out, _ = plant.communicate()
        bus.shutdown()
    return {"feedback": len(angles), "first_rad": angles[0] if angles else None,
            "last_rad": angles[-1] if angles else None, "states": sorted(states), "rejected": rejected,
            "plant_output": out[-2000:]}


if __name__ == "__main__":
    print(json.dumps(drive(sys.argv[1])))
