"""The CiA 402 bus budget of docs/cia402.md, recomputed by hand from the classic CAN frame formula (8n + 47 bits
plus worst-case stuffing floor((34 + 8n - 1) / 4), interframe space included): SYNC 55, a 2-byte RPDO 75, an 8-byte
TPDO 135 bits."""
from __future__ import annotations

from sea_hil.protocol.cia402_budget import budget, max_sync_rate_hz, sync_frames


def test_one_limb_fits_at_1_khz() -> None:
    assert sync_frames(1) == [0, 8, 8, 2, 8, 8, 2]            # SYNC; per node TPDO 2, TPDO 3, RPDO 2
    b = budget(1)
    assert b.bits_per_sync_worst == 55 + 2 * (135 + 135 + 75) == 745
    assert b.load_pct_worst == 74.5 and b.bits_per_sync_nominal == 47 + 2 * (111 + 111 + 63)
    assert b.background_pct_worst == 100 * 2 * (65 * 10 + 85 * 20) / 1e6    # heartbeat 10 Hz, TPDO 1 20 Hz
    assert b.load_pct_worst + b.background_pct_worst < 80.0   # under the session's bus_load_warn_pct


def test_two_limbs_do_not_fit_at_1_khz() -> None:
    assert budget(2).load_pct_worst > 100.0
    assert 600 < max_sync_rate_hz(2) < 700                     # 697 Hz: a 1.5 ms SYNC period fits two limbs
