"""A full multi-process HIL session through the real ``vcan0``: ``sea-hil plant``, ``edge``, ``record`` and
``controller`` as separate processes (the plant and the edge share nothing but the kernel's vcan0), in lockstep.

Lockstep is deterministic and independent of the bus, so the session's summary must equal that of ``sea-hil run
--lockstep`` on the embedded virtual bus with the same config in every deterministic field
(tests/summary_compare.py). Evidence that frames crossed vcan0: the lockstep plant process advanced one sample per VOLTAGE_CMD of the edge process, ``candump``
(can-utils) sees those frames, and the recorder (another process, own socket) records both directions. A 1 s slice
of the gait keeps guest time small.
"""
from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pytest
from session_nodes import GaitSlice, NodeSession, run_node_session, write_client_config
from socketcan_helpers import CanDump
from summary_compare import deterministic

STATE_PERIOD_S = 0.01           # default controller.sample_period_s


def voltage_cmd_id(node_id: int) -> int:
    """CAN id of node ``node_id``'s VOLTAGE_CMD, from the DBC."""
    from sea_hil.protocol.can_codec import SeaCodec
    from sea_hil.protocol.can_frames import VoltageCmd
    return int(SeaCodec().encode(VoltageCmd(node_id, (0.0, 0.0), 0)).arbitration_id)


def test_multiprocess_session_on_vcan0_matches_virtual_bus(tmp_path: Path, vcan_channel: str, gait_slice: GaitSlice,
                                                           start_candump: Callable[..., CanDump]) -> None:
    from sea_hil.protocol.zsession import free_tcp_port
    config = gait_slice.config
    cmd_id = voltage_cmd_id(1)
    dump = start_candump("-n", "5", filters=f"{cmd_id:03X}:7FF")
    out = tmp_path / "vcan"
    out.mkdir()
    session = NodeSession(config=config, client_config=write_client_config(tmp_path), can=f"socketcan:{vcan_channel}",
                          listen_host="127.0.0.1", port=free_tcp_port())
    result = run_node_session(session, out)
    summary, data = result.summary, result.data

    # the session completed the slice, and ET transmitted less than it received
    samples = int(round(gait_slice.duration_s / STATE_PERIOD_S))
    assert summary["duration_s"] == pytest.approx(gait_slice.duration_s, abs=STATE_PERIOD_S)
    tx = summary["transmissions"]
    published = summary["edge"]["uplink_msgs"]      # the edge's own count (the recorder may join a state late)
    assert samples <= published <= samples + 2, summary["edge"]
    assert 0 < tx["downlink_msgs"] < published, (tx, published)
    # every setpoint the edge applied is recorded: lockstep publishes with BLOCK (sea_hil/runtime/lockstep.py). With
    # DROP, 2 of 12 guest runs lost the last one on the recorder's link (52 applied, 51 recorded); on failure, the
    # counts of every observer
    assert summary["timing"]["latency_samples"] == tx["downlink_msgs"], {
        "latency_samples": summary["timing"]["latency_samples"], "recorded_downlink": tx["downlink_msgs"],
        "lead_in": summary.get("lead_in"), "edge_downlink_applied": summary["edge"].get("downlink_applied"),
        "edge_timing": summary["timing"].get("edge"), "late_setpoints": summary["edge"].get("late_setpoints")}
    assert json.loads((out / "summary.json").read_text())["tracking"] == summary["tracking"]

    # frames really crossed vcan0. The lockstep plant (its own process) advances a sample only on the edge's
    # VOLTAGE_CMD answering it: every tick is a command that crossed vcan0.
    fb_samples = summary["edge"]["feedback_samples"]
    assert fb_samples >= gait_slice.duration_s * 1000, summary["edge"]
    assert result.plant_report.startswith("ticks "), result.plant_report
    assert int(result.plant_report.split()[1]) >= fb_samples - 1, result.plant_report
    # can-utils' candump saw the edge's commands on vcan0
    frames = [dump.next_frame(timeout_s=30.0) for _ in range(5)]
    assert all(f is not None and f.channel == vcan_channel and f.arbitration_id == cmd_id for f in frames), frames
    # the recorder's socket saw both directions, every frame (issue 32: the four-process topology on SocketCAN
    # loses nothing): each channel's count equals the node's own counter, no CAN sequence gap
    feedback, commands = data.messages.get("/can/feedback", []), data.messages.get("/can/command", [])
    assert len(feedback) > 0, summary["edge"]
    completeness = summary["completeness"]
    assert completeness["complete"] and completeness["can_frames_lost"] == 0, completeness
    can_cmd = completeness["channels"]["can_command"]    # the edge's commands_sent + arrival_commands
    assert len(commands) == can_cmd["recorded"] == can_cmd["expected"] >= summary["edge"]["commands_sent"], can_cmd
    print(f"completeness: {completeness['channels']}")
    print(f"vcan0 session: plant '{result.plant_report}', edge commands {summary['edge']['commands_sent']}, "
          f"recorded CAN commands {len(commands)} feedback frames {len(feedback)}, tracking {summary['tracking']}, "
          f"transmissions {tx}")

    # lockstep is deterministic: the single-process run on the virtual bus has the same summary in every
    # deterministic field (tracking, setpoints, events, the edge's counters, completeness, verdict)
    assert deterministic(summary) == deterministic(gait_slice.reference)
