"""Issue 31 on a real SocketCAN vcan0 (in the UML guest: scripts/with-vcan -- .venv/bin/python -m pytest -q
tests/socketcan/test_cia402_vcan.py):

- the whole acceptance list of tests/test_cia402_master.py (python canopen's `BaseNode402` master, the drive on its
  test clock) with both ends on vcan0 instead of the virtual bus;
- `sea-hil plant --can-profile cia402` as its own process in real time, a canopen master sending SYNC and the target
  torque every 10 ms from the kernel's broadcast manager, and `candump -L` showing boot-up, heartbeat, SYNC, PDO and
  EMCY frames with the documented ids and timing (docs/cia402.md).
"""
from __future__ import annotations

import contextlib
import itertools
import queue
import statistics
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import canopen
import pytest
from canopen.profiles.p402 import BaseNode402

from sea_hil.protocol.cia402_eds import eds_path
from tests.cia402_rig import Rig, cia402_config
from tests.test_cia402_master import (  # noqa: F401  (the acceptance tests, run here on vcan0 too)
    test_cst_moves_the_limb_as_the_plant_model,
    test_keeps_working_after_1000_malformed_frames,
    test_nmt_reset_sdo_identity_and_segmented_transfers,
    test_pdo_mapping_read_and_changed_over_sdo,
    test_sdo_abort_codes,
    test_soft_limit_emcy_fault_and_fault_reset,
)

REPO = Path(__file__).resolve().parents[2]
DEADLINE_S = 120.0          # UML syscalls are slow: generous, bounded
SYNC_PERIOD_S = 0.01


@pytest.fixture
def rig(vcan_channel: str) -> Iterator[Rig]:
    r = Rig(cia402_config(), "socketcan", vcan_channel)
    try:
        yield r
    finally:
        r.close()


def _end(proc: subprocess.Popen[str]) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=10.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=10.0)


def _until(what: Callable[[], bool], timeout_s: float = DEADLINE_S) -> None:
    end = time.monotonic() + timeout_s
    while not what():
        assert time.monotonic() < end, "timed out"


def _candump(path: Path) -> dict[int, list[tuple[float, bytes]]]:
    """`candump -L` lines of `path` by id: (timestamp s, data)."""
    by_id: dict[int, list[tuple[float, bytes]]] = {}
    for line in path.read_text().splitlines():
        stamp, _, frame = line.split()
        can_id, data = frame.split("#", 1)
        by_id.setdefault(int(can_id, 16), []).append((float(stamp.strip("()")), bytes.fromhex(data)))
    return by_id


def test_plant_process_master_and_candump(vcan_channel: str, tmp_path: Path) -> None:
    log = (tmp_path / "candump.log").open("w")
    dump = subprocess.Popen(["candump", "-L", vcan_channel], stdout=log, stderr=subprocess.DEVNULL, text=True)
    proc = subprocess.Popen([sys.executable, "-m", "sea_hil.cli", "plant", "--can-profile", "cia402", "--can",
                             f"socketcan:{vcan_channel}", "--duration", "600",
                             "--watchdog", "5"],   # 0x2012 = 5 s: the slow guest delays frames (test_driver_vcan)
                            cwd=REPO, text=True, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    network = canopen.Network()
    try:
        network.connect(interface="socketcan", channel=vcan_channel)
        hip = BaseNode402(1, str(eds_path("hip")))
        network.add_node(hip)
        hip.sdo.RESPONSE_TIMEOUT = 10.0           # the drive process in the slow guest: bounded but generous
        for name in ("TIMEOUT_SWITCH_OP_MODE", "TIMEOUT_SWITCH_STATE_FINAL", "TIMEOUT_SWITCH_STATE_SINGLE",
                     "TIMEOUT_CHECK_TPDO"):
            setattr(hip, name, 10.0)
        hip.nmt.wait_for_bootup(DEADLINE_S)
        assert hip.sdo[0x1000].raw == 0x00020192
        hip.setup_402_state_machine()
        hip.nmt.state = "OPERATIONAL"
        hip.state = "OPERATION ENABLED"
        hip.op_mode = "CYCLIC SYNCHRONOUS TORQUE"
        positions: queue.Queue[int] = queue.Queue()
        hip.tpdo[2].add_callback(lambda m: positions.put(m["Position actual value"].raw))
        hip.rpdo[2]["Target torque"].raw = 50
        network.sync.start(SYNC_PERIOD_S)                 # SYNC and the target from the kernel's BCM
        hip.rpdo[2].start(SYNC_PERIOD_S)
        first = positions.get(timeout=DEADLINE_S)
        _until(lambda: positions.get(timeout=DEADLINE_S) - first > 5000)      # moved 5 mrad
        emcys: queue.Queue[int] = queue.Queue()
        hip.emcy.add_callback(lambda err: emcys.put(err.code))
        hip.sdo[0x607D][2].raw = positions.get(timeout=DEADLINE_S) + 2000
        assert emcys.get(timeout=DEADLINE_S) == 0x8612
        beats: queue.Queue[int] = queue.Queue()
        hip.nmt.add_heartbeat_callback(beats.put)
        for _ in range(5):                                 # half a second of operational heartbeats in the log
            _until(lambda: beats.get(timeout=DEADLINE_S) == 0x05)
        hip.rpdo[2].stop()
        network.sync.stop()
        end = time.monotonic() + DEADLINE_S
        with contextlib.suppress(queue.Empty):           # a stalled guest's drive works through its backlog of
            while time.monotonic() < end:                # SYNCs: wait until its TPDO 2 stream is quiet for 3 s
                positions.get(timeout=3.0)
    finally:
        network.disconnect()
        _end(proc)
        _end(dump)
        log.close()
    assert proc.stdout is not None
    stats_line = proc.stdout.read().strip().splitlines()[-1].split()
    drive = dict(zip(stats_line[::2], map(int, stats_line[1::2]), strict=True))
    by_id = _candump(tmp_path / "candump.log")
    assert by_id[0x701][0][1] == b"\x00" and by_id[0x702][0][1] == b"\x00"          # boot-up
    ops = [t for t, d in by_id[0x701] if d == b"\x05"]                                 # operational heartbeats
    gaps_ms = [1e3 * (b - a) for a, b in itertools.pairwise(ops)]
    rate_hz = len(gaps_ms) / (ops[-1] - ops[0])          # 0x1017 = 100 ms: 10 Hz on average, stalls or not (a
    assert len(gaps_ms) >= 3 and 5.0 <= rate_hz <= 11.0, gaps_ms   # stalled guest sends late beats back to back)
    assert all(d == b"" for _, d in by_id[0x080])                                      # SYNC, no counter
    assert 0x181 in by_id and 0x281 in by_id and 0x381 in by_id and 0x301 in by_id    # TPDO 1-3, RPDO 2
    sync_times = [t for t, _ in by_id[0x080]]
    lag_ms = [1e3 * (t - max(s for s in sync_times if s <= t)) for t, _ in by_id[0x281] if t >= sync_times[0]]
    per_sync = [sum(s <= t < s + SYNC_PERIOD_S for t, _ in by_id[0x281] + by_id[0x381] + by_id[0x301])
                for s in sync_times[:-1]]
    print(f"cia402 vcan: heartbeat {rate_hz:.2f} Hz, gap median {statistics.median(gaps_ms):.1f} ms, TPDO 2 after SYNC median "
          f"{statistics.median(lag_ms):.2f} ms (p90 {sorted(lag_ms)[int(0.9 * len(lag_ms))]:.2f}), frames per SYNC "
          f"median {statistics.median(per_sync)} over {len(sync_times)} SYNCs")
    answered = [t for t, _ in by_id[0x281] if t >= sync_times[0]]
    print(f"cia402 vcan: SYNCs on the bus {len(sync_times)}, received by the drive {drive['node1_syncs']}, TPDO 2 "
          f"sent {drive['node1_tpdo2_sent']}, in candump {len(answered)}; send failures {drive['send_failures']}")
    assert drive["node1_tpdo2_sent"] == drive["node1_syncs"] > 0     # every SYNC the drive received is answered
    assert len(answered) == len(sync_times) == drive["node1_syncs"]    # none lost, however late
    emcy = [d for _, d in by_id[0x081]]
    assert any(d[:3] == bytes([0x12, 0x86, 0x21]) for d in emcy), emcy                 # 0x8612, register 0x21
