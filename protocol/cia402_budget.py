"""The CiA 402 profile's bus budget (docs/cia402.md, "Bus budget"): frames per SYNC and the bus load of the default
PDO set (`cia402_od.RPDO_DEFAULTS` / `TPDO_DEFAULTS`) from the frames' bit lengths (`sea_hil.stats.can_bits`,
classic CAN, 11-bit ids, worst-case and no bit stuffing). `python -m sea_hil.protocol.cia402_budget` prints the
table the page quotes."""
from __future__ import annotations

from typing import NamedTuple

from sea_hil.protocol.cia402_od import PDO_INVALID, RPDO_DEFAULTS, TPDO_DEFAULTS, TPDO_EVENT_TIMER_MS
from sea_hil.stats.can_bits import can_frame_bits


class Budget(NamedTuple):
    frames_per_sync: int
    bits_per_sync_worst: int
    bits_per_sync_nominal: int
    load_pct_worst: float
    load_pct_nominal: float
    background_pct_worst: float     # heartbeats and the event-timer statusword TPDO, on top


def background_bits_per_s(limbs: int, heartbeat_ms: int = 100) -> int:
    """Worst-case bits per second of what is not per SYNC: each node's heartbeat (1 byte) and its statusword TPDO 1
    (3 bytes) at its event timer."""
    tpdo1 = sum(bits for _, bits in TPDO_DEFAULTS[0][2]) // 8
    per_node = can_frame_bits(1) * 1000 // heartbeat_ms + can_frame_bits(tpdo1) * 1000 // TPDO_EVENT_TIMER_MS
    return 2 * limbs * per_node


def sync_frames(limbs: int, mode_target: int = 0x6071) -> list[int]:
    """Data lengths (bytes) of the frames of one SYNC period: the SYNC (0 bytes), then per node the synchronous
    enabled TPDOs and the one RPDO carrying the active mode's target (`mode_target`: 0x6071 CST, 0x2000 voltage)."""
    out = [0]
    for _ in range(2 * limbs):
        out += [sum(bits for _, bits in mapped) // 8 for cob, ttype, mapped in TPDO_DEFAULTS
                if not cob & PDO_INVALID and ttype <= 240]
        out += [sum(bits for _, bits in mapped) // 8 for cob, ttype, mapped in RPDO_DEFAULTS
                if not cob & PDO_INVALID and any(index == mode_target for index, _ in mapped)]
    return out


def budget(limbs: int = 1, sync_rate_hz: float = 1000.0, bitrate_bps: int = 1_000_000) -> Budget:
    lengths = sync_frames(limbs)
    worst = sum(can_frame_bits(n) for n in lengths)
    nominal = sum(can_frame_bits(n, worst_case=False) for n in lengths)
    return Budget(len(lengths), worst, nominal, 100.0 * worst * sync_rate_hz / bitrate_bps,
                  100.0 * nominal * sync_rate_hz / bitrate_bps, 100.0 * background_bits_per_s(limbs) / bitrate_bps)


def max_sync_rate_hz(limbs: int, bitrate_bps: int = 1_000_000, max_load_pct: float = 100.0) -> float:
    """The highest SYNC rate at which the worst-case frames of one period fit in `max_load_pct` of the bus."""
    return max_load_pct / 100.0 * bitrate_bps / budget(limbs).bits_per_sync_worst


if __name__ == "__main__":
    for n in (1, 2):
        b = budget(n)
        print(f"{n} limb(s), 1 kHz SYNC, 1 Mbit/s: {b.frames_per_sync} frames/SYNC, {b.bits_per_sync_worst} bits "
              f"worst case ({b.load_pct_worst:.1f} %), {b.bits_per_sync_nominal} bits unstuffed "
              f"({b.load_pct_nominal:.1f} %), + {b.background_pct_worst:.2f} % heartbeats and statusword; fits 100 % "
              f"up to {max_sync_rate_hz(n):.0f} Hz, 80 % up to "
              f"{max_sync_rate_hz(n, max_load_pct=80.0):.0f} Hz")
