"""Limbs as data (issue 17): the limb list and its bus assignment (pure, milliseconds), the edge multiplexer's
dispatch (fake cores), and one short lockstep session pair with two limbs: on two buses (`--limbs 2`) and on one
shared bus (`[[limbs]]`: one driver node serving both node ids, one `EdgeMux`); every limb's deterministic fields are
equal across the two runs and equal to the 1-limb lockstep result (the offline session engine's replay)."""
from __future__ import annotations

import copy
import tomllib
from pathlib import Path

import can
import pytest

from sea_hil.config.loader import config_to_toml, load_config
from sea_hil.controller.edge_mux import EdgeMux
from sea_hil.errors import ConfigError
from sea_hil.offline.session_engine import run_engine
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import Feedback
from sea_hil.report.session_summary import session_summary
from sea_hil.report.summary import deterministic
from sea_hil.session.limbs import (
    Limb,
    bus_specs,
    buses_of,
    expand_limbs,
    limb_config,
    limb_load_pct,
    limbs_per_bus,
    session_limbs,
)
from sea_hil.session.run import RunOptions, run_session

SHORT = {"trajectory": {"period_s": 2.0}, "safety": {"drive": {"enabled": False}, "setpoint": {"enabled": False}}}


def test_one_limb_is_todays_limb() -> None:
    cfg = load_config()
    assert session_limbs(cfg) == (Limb("limb1", 1, "virtual:sea-hil"),) == expand_limbs(cfg, 1)
    assert limb_config(cfg, session_limbs(cfg)[0]).zenoh == cfg.zenoh


def test_classic_can_carries_one_limb_per_bus() -> None:
    cfg = load_config()
    assert limb_load_pct(cfg) == pytest.approx(51.135)      # docs/can-protocol.md: 51.1 % of 1 Mbit/s
    assert limbs_per_bus(cfg) == 1 and limbs_per_bus(cfg, max_load=1.0) == 1
    limbs = expand_limbs(cfg, 4)
    assert [(x.name, x.node_id) for x in limbs] == [("limb1", 1), ("limb2", 2), ("limb3", 3), ("limb4", 4)]
    assert [x.bus for x in limbs] == [f"virtual:sea-hil{i}" for i in range(4)]


def test_a_faster_bus_fills_before_the_next() -> None:
    cfg = load_config(overrides={"can": {"bitrate_bps": 2_500_000}})   # 0.8 * 2.5 Mbit/s / 511 kbit/s = 3.9
    assert limbs_per_bus(cfg) == 3
    limbs = expand_limbs(cfg, 4, node_id=5, spec="socketcan:vcan0")
    assert {b: [x.node_id for x in ls] for b, ls in buses_of(limbs).items()} == \
        {"socketcan:vcan0": [5, 6, 7], "socketcan:vcan1": [8]}


def test_can_fd_carries_four_limbs_per_bus() -> None:
    cfg = load_config(overrides={"can": {"fd": True}})      # 16.4 % a limb at 1 / 5 Mbit/s
    assert limbs_per_bus(cfg) == 4
    assert [x.bus for x in expand_limbs(cfg, 6)] == ["virtual:sea-hil0"] * 4 + ["virtual:sea-hil1"] * 2


def test_bus_specs_count_up() -> None:
    assert bus_specs("socketcan:vcan3", 2) == ["socketcan:vcan3", "socketcan:vcan4"]
    assert bus_specs("virtual:x", 1) == ["virtual:x"]
    assert bus_specs("udp_multicast:239.74.163.2", 2) == ["udp_multicast:239.74.163.2", "udp_multicast:239.74.163.3"]
    with pytest.raises(ConfigError):
        bus_specs("socketcan:abcdefghijklmn9", 2)   # abcdefghijklmn10: 16 characters, not an interface name


def test_bad_limb_lists_are_config_errors() -> None:
    cfg = load_config()
    with pytest.raises(ConfigError, match="--limbs must be >= 1"):
        expand_limbs(cfg, 0)
    with pytest.raises(ConfigError, match="largest node id"):
        expand_limbs(cfg, 4, node_id=61)
    for limbs, what in (([{"name": "a", "node_id": 1}, {"name": "a", "node_id": 2}], "name must be unique"),
                        ([{"name": "a", "node_id": 1}, {"name": "b", "node_id": 1}], "node_id must be unique"),
                        ([{"name": "a/b", "node_id": 1}], "must not contain"),
                        ([{"name": "a", "node_id": 1, "bus": "nonsense"}], "bad CAN spec")):
        with pytest.raises(ConfigError, match=what):
            load_config(overrides={"limbs": limbs})
    two = load_config(overrides={"limbs": [{"name": "left", "node_id": 3}, {"name": "right", "node_id": 4}]})
    with pytest.raises(ConfigError, match="contradicts"):
        session_limbs(two, 3)
    assert session_limbs(two) == (Limb("left", 3, "virtual:sea-hil"), Limb("right", 4, "virtual:sea-hil"))
    assert tomllib.loads(config_to_toml(two))["limbs"] == [{"name": "left", "node_id": 3, "bus": ""},
                                                          {"name": "right", "node_id": 4, "bus": ""}]


class _Core:
    def __init__(self, node_id: int) -> None:
        self.node_id, self.got = node_id, []

    def on_can(self, msg: can.Message, rx_ns: int) -> None:
        self.got.append(msg.arbitration_id)

    def stop(self) -> None:
        pass

    def close(self) -> None:
        pass


def test_edge_mux_dispatches_by_node_id() -> None:
    a, b = _Core(1), _Core(2)
    mux = EdgeMux(None, [a, b])  # type: ignore[arg-type,list-item]

    def frame(can_id: int, n: int = 8) -> can.Message:
        return can.Message(arbitration_id=can_id, data=bytes(n), is_extended_id=False)

    for can_id in (1 << 5 | 0x01, 2 << 5 | 0x01, 2 << 5 | 0x02):
        mux.dispatch(frame(can_id), 0)
    zero = (0.0, 0.0)
    for msg in SeaCodec([3]).encode_feedback(Feedback(3, 0, 0, zero, zero, zero, zero)):
        mux.dispatch(msg, 0)                   # node 3's well-formed frames: another device's, dropped and counted
    mux.dispatch(frame(0x7FF, 1), 0)           # unknown id: to the first core, which rejects and counts it
    assert b.got == [2 << 5 | 0x01, 2 << 5 | 0x02]
    assert a.got == [1 << 5 | 0x01, 0x7FF] and mux.foreign_frames == 3
    with pytest.raises(ConfigError):
        EdgeMux(None, [a, _Core(1)])  # type: ignore[arg-type,list-item]


@pytest.mark.slow
def test_two_limbs_in_lockstep_match_one_limb(tmp_path: Path) -> None:
    two_buses = run_session(load_config(overrides=SHORT),
                            RunOptions(out=tmp_path / "two_buses", lockstep=True, progress=False, figures=False,
                                       limbs=2))
    shared = {**SHORT, "limbs": [{"name": "limb1", "node_id": 1}, {"name": "limb2", "node_id": 2}]}
    one_bus = run_session(load_config(overrides=shared),
                          RunOptions(out=tmp_path / "one_bus", lockstep=True, progress=False, figures=False))
    assert [e["bus"] for e in two_buses["limbs"]] == ["virtual:sea-hil0", "virtual:sea-hil1"]
    assert [e["bus"] for e in one_bus["limbs"]] == ["virtual:sea-hil"] * 2
    a, b = copy.deepcopy(deterministic(two_buses)), copy.deepcopy(deterministic(one_bus))
    for s in (a, b):
        s["limbs_total"].pop("buses")
        for e in s["limbs"]:
            e.pop("bus")
    assert a == b          # every deterministic field, the first limb's edge counters included
    assert (two_buses["limbs_total"]["buses"], one_bus["limbs_total"]["buses"]) == (2, 1)
    assert two_buses["limbs_total"]["transmissions"]["uplink_msgs"] == 2 * two_buses["transmissions"]["uplink_msgs"]
    one = session_summary(run_engine(load_config(overrides=SHORT), "et").data, "et")   # 1-limb lockstep, replayed
    for e in a["limbs"]:
        assert e["tracking"] == one["tracking"] and e["transmissions"] == one["transmissions"]
    assert two_buses["timing"]["driver"]["tick_misses"] == 0
