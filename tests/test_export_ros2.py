"""`sea-hil export RUN.mcap --ros2 DIR` (issue 30, docs/ros2.md): the bag is decoded by readers that are not the
exporter's code -- mcap-ros2-support's `DecoderFactory` through `mcap.reader`, and under node npm `@mcap/core` with
Foxglove's ros2msg parser and CDR reader (tests/js/check_ros2_bag.mjs) -- and every value is checked against the
source recording read by `read_session`: CAN ids and payload bytes frame by frame, joint angles sample by sample,
counts per topic; metadata.yaml against the MCAP file; every schema a ROS 2 standard type or a shipped
sea_hil_msgs one. Two short lockstep sessions (one limb, two limbs) are exported once per module; real-time style
recordings, CAN FD and bad input: tests/test_export_ros2_input.py."""
from __future__ import annotations

import json
import re
import shutil
import subprocess
from collections import Counter
from importlib import resources
from pathlib import Path
from typing import Any

import pytest
import yaml
from ros2_bag import export, t_ns

from sea_hil.config.loader import load_config
from sea_hil.errors import MalformedFrame
from sea_hil.mechanics import limb_params, sea_geometry
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import Heartbeat
from sea_hil.recorder.reader import SessionData, read_session
from sea_hil.session.run import RunOptions, run_session

JS = Path(__file__).resolve().parent / "js"
NODE = shutil.which("node")
SHORT = {"trajectory": {"period_s": 0.5}}
ALLOWED_PACKAGES = {"builtin_interfaces", "std_msgs", "sensor_msgs", "can_msgs", "ros2_socketcan_msgs",
                    "rcl_interfaces", "diagnostic_msgs", "sea_hil_msgs"}
TOPICS = ("from_can_bus", "joint_states", "joint_states_desired", "state", "setpoint")


@pytest.fixture(scope="module")
def one_limb(tmp_path_factory) -> tuple[SessionData, dict[str, Any], Path]:
    out = tmp_path_factory.mktemp("ros2") / "run"
    run_session(load_config(overrides=SHORT), RunOptions(controller="et", out=out, lockstep=True, progress=False,
                                                         figures=False))
    bag = out.parent / "bag"
    return read_session(out / "session.mcap"), export(out / "session.mcap", bag), bag


@pytest.fixture(scope="module")
def two_limbs(tmp_path_factory) -> tuple[SessionData, dict[str, Any], Path]:
    out = tmp_path_factory.mktemp("ros2") / "run2"
    run_session(load_config(overrides=SHORT), RunOptions(controller="et", out=out, lockstep=True, progress=False,
                                                         figures=False, limbs=2))
    bag = out.parent / "bag2"
    return read_session(out / "session.mcap"), export(out / "session.mcap", bag), bag


def heartbeats(src: SessionData) -> list[Heartbeat]:
    codec, out = SeaCodec(fd=None), []
    for m in src.messages["/can/raw"]:
        p = m.payload
        try:
            d = codec.decode_raw(p["can_id"], bytes.fromhex(p["data_hex"]), p["dlc"])
        except MalformedFrame:   # frames the DBC refuses are not heartbeats
            continue
        if isinstance(d, Heartbeat):
            out.append(d)
    return out


def expected_joint_states(src: SessionData) -> list[tuple[int, int, list[float], list[float], list[float]]]:
    """(node, log time, position, velocity, deflections) per drive sample from the recorded feedback frames: a
    FEEDBACK_ANGLE and the two JOINT frames of the same seq at the same log time (lockstep: log time = sample time);
    a re-sent sample once."""
    fb = src.messages["/can/feedback"]
    parts: dict[tuple[Any, int, int], dict[str, float]] = {}
    for m in fb:
        parts.setdefault((m.payload["node_id"], m.log_time_ns, m.payload["seq"]), {}).update(m.payload)
    out, seen = [], set()
    for m in fb:
        p = m.payload
        if "t_us" not in p or (p["node_id"], m.log_time_ns) in seen:
            continue
        seen.add((p["node_id"], m.log_time_ns))
        v = parts[(p["node_id"], m.log_time_ns, p["seq"])]
        out.append((p["node_id"], m.log_time_ns, [v["theta1_rad"], v["theta2_rad"]],
                    [v["omega1_rad_s"], v["omega2_rad_s"]], [v["delta1_m"], v["delta2_m"]]))
    return out


def test_every_message_decodes_and_matches_the_recording(one_limb):
    src, bag, _ = one_limb
    msgs = bag["messages"]
    assert set(msgs) == {f"/{t}" for t in TOPICS} | {"/rosout", "/diagnostics"}
    raw = src.messages["/can/raw"]
    frames = msgs["/from_can_bus"]
    assert len(frames) == len(raw) > 1000
    for r, (log, pub, seq, f) in zip(raw, frames, strict=True):
        p = r.payload
        assert (f.id, f.dlc, f.is_extended, f.is_rtr, f.is_error) == (p["can_id"], p["dlc"], p["is_extended"], False,
                                                                      False)
        assert bytes(f.data)[:p["dlc"]] == bytes.fromhex(p["data_hex"]) and len(bytes(f.data)) == 8
        assert log == pub == r.log_time_ns == t_ns(f.header.stamp) and seq == r.sequence   # lockstep: sample time
        assert f.header.frame_id == "can"

    want = expected_joint_states(src)
    got = msgs["/joint_states"]
    assert len(got) == len(want) > 500
    params = limb_params(load_config(overrides=SHORT).plant)
    for (_, log, pos, vel, delta), (blog, _, _, js) in zip(want, got, strict=True):
        assert (list(js.name), t_ns(js.header.stamp), blog) == (["hip", "knee"], log, log)
        assert list(js.position) == pos and list(js.velocity) == vel
        _, _, a1, a2, _, _ = sea_geometry(pos[0], pos[1], params)      # Eq. 4: tau = -k Delta a
        assert list(js.effort) == pytest.approx([-params.k1 * delta[0] * a1, -params.k2 * delta[1] * a2], rel=1e-12)

    tracking = src.messages["/tracking"]
    desired = msgs["/joint_states_desired"]
    assert len(desired) == len(tracking) > 50
    for t, (log, _, _, js) in zip(tracking, desired, strict=True):
        assert list(js.position) == [t.payload["theta1_d_rad"], t.payload["theta2_d_rad"]] and log == t.log_time_ns
        assert list(js.velocity) == [] and list(js.effort) == []

    states = src.messages["/zenoh/state"]
    assert len(msgs["/state"]) == len(states) > 5
    for s, (_, _, _, b) in zip(states, msgs["/state"], strict=True):
        p = s.payload
        assert (b.seq, b.theta1_rad, b.theta2_rad, b.delta2_m, b.reason, b.event_seq, b.trajectory_id) == \
            (p["seq"], p["theta1_rad"], p["theta2_rad"], p["delta2_m"], p["reason"], p["event_seq"],
             p["trajectory_id"])
        assert t_ns(b.header.stamp) == p["sample_t_ns"]
    sample_of = {s.payload["seq"]: s.payload["sample_t_ns"] for s in states}
    setpoints = src.messages["/zenoh/setpoint"]
    assert len(msgs["/setpoint"]) == len(setpoints) > 5
    for s, (_, _, _, b) in zip(setpoints, msgs["/setpoint"], strict=True):
        p = s.payload
        assert (b.seq, b.state_seq, b.delta1_ref_m, b.delta2_ref_m, b.s1, b.reason) == \
            (p["seq"], p["state_seq"], p["delta1_ref_m"], p["delta2_ref_m"], p["s1"], p["reason"])
        if p["state_seq"] in sample_of:          # stamped at the sample time of the state it answers
            assert t_ns(b.header.stamp) == sample_of[p["state_seq"]]

    logs = src.messages["/log/events"] + src.messages["/log/faults"]
    rosout = [m[3] for m in msgs["/rosout"]]
    assert Counter(r.msg for r in rosout) == Counter(m.payload["message"] for m in logs) and len(rosout) > 5
    assert {r.level for r in rosout} <= {10, 20, 30, 40, 50} and any(r.name == "driver1" for r in rosout)

    diags = [m[3] for m in msgs["/diagnostics"]]
    hbs = heartbeats(src)
    assert len(diags) == len(hbs) + len(src.messages["/stats"]) + 1 and hbs
    names = Counter(d.status[0].name for d in diags)
    assert names["driver1"] == len(hbs) and names["recorder"] == 1 and names["edge"] == 1
    edge = next(d.status[0] for d in diags if d.status[0].name == "edge")
    stats = next(m.payload for m in src.messages["/stats"] if m.payload["node"] == "edge")
    assert {kv.key: kv.value for kv in edge.values}["uplink_msgs"] == str(stats["uplink_msgs"])


def test_metadata_yaml_is_rosbag2s_and_counts_the_file(one_limb):
    _, bag, directory = one_limb
    meta = yaml.safe_load((directory / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    name = f"{directory.name}_0.mcap"
    assert sorted(p.name for p in directory.iterdir()) == sorted([name, "metadata.yaml"])
    assert (meta["version"], meta["storage_identifier"], meta["relative_file_paths"]) == (8, "mcap", [name])
    assert (meta["compression_format"], meta["compression_mode"], meta["ros_distro"]) == ("", "", "")
    stats = bag["statistics"]
    counts = {t: len(v) for t, v in bag["messages"].items()}
    assert meta["message_count"] == sum(counts.values()) == stats.message_count
    assert meta["starting_time"]["nanoseconds_since_epoch"] == stats.message_start_time
    assert meta["duration"]["nanoseconds"] == stats.message_end_time - stats.message_start_time > 0
    assert meta["files"] == [{"path": name, "starting_time": meta["starting_time"], "duration": meta["duration"],
                              "message_count": meta["message_count"]}]
    topics = {t["topic_metadata"]["name"]: t for t in meta["topics_with_message_count"]}
    assert {t: v["message_count"] for t, v in topics.items()} == counts
    for topic, info in topics.items():
        tm = info["topic_metadata"]
        schema, encoding, ch_meta = bag["channels"][topic]
        assert (tm["type"], tm["serialization_format"], encoding) == (schema, "cdr", "cdr")
        assert tm["offered_qos_profiles"] == ch_meta["offered_qos_profiles"]
        (qos,) = yaml.safe_load(tm["offered_qos_profiles"])
        assert set(qos) == {"history", "depth", "reliability", "durability", "deadline", "lifespan", "liveliness",
                            "liveliness_lease_duration", "avoid_ros_namespace_conventions"}
        assert all(isinstance(qos[k], int) for k in ("history", "depth", "reliability", "durability", "liveliness"))
    assert yaml.safe_load(bag["metadata"]["rosbag2"]["serialized_metadata"]) == meta   # as rosbag2 also writes it
    assert meta["custom_data"]["sea_hil.log_time_clock"] == "sample"


def _check_schemas(bag: dict[str, Any]) -> None:
    assert bag["profile"] == "ros2"
    for name, (encoding, text) in bag["schemas"].items():
        assert encoding == "ros2msg" and re.fullmatch(r"[a-z_]+/msg/[A-Za-z]+", name)
        assert name.split("/")[0] in ALLOWED_PACKAGES, name
        deps = re.findall(r"^MSG: ([a-z_]+)/([A-Za-z]+)$", text, flags=re.M)
        assert {pkg for pkg, _ in deps} <= ALLOWED_PACKAGES, deps
        if "std_msgs/Header header" in text:
            assert ("std_msgs", "Header") in deps and ("builtin_interfaces", "Time") in deps   # full text, no lookup
        if name.startswith("sea_hil_msgs/"):
            shipped = resources.files("sea_hil.ros2").joinpath(f"sea_hil_msgs/msg/{name.split('/')[-1]}.msg")
            assert text.startswith(shipped.read_text(encoding="utf-8"))
    for _, encoding, _ in bag["channels"].values():
        assert encoding == "cdr"


def test_every_schema_is_a_ros2_standard_type_or_a_shipped_sea_hil_msg(one_limb, two_limbs):
    for _, bag, _ in (one_limb, two_limbs):
        _check_schemas(bag)
    assert {n.split("/")[0] for n in one_limb[1]["schemas"]} == ALLOWED_PACKAGES - {"builtin_interfaces", "std_msgs",
                                                                                   "ros2_socketcan_msgs"}


def test_two_limbs_get_a_namespace_each(two_limbs):
    src, bag, _ = two_limbs
    msgs = bag["messages"]
    assert set(msgs) == {f"/limb{n}/{t}" for n in (1, 2) for t in TOPICS} | {"/rosout", "/diagnostics"}
    for n in (1, 2):
        raw = [m for m in src.messages["/can/raw"] if m.payload["node_id"] == n]
        frames = [f for *_, f in msgs[f"/limb{n}/from_can_bus"]]
        assert [(f.id, bytes(f.data)[:f.dlc]) for f in frames] == \
            [(m.payload["can_id"], bytes.fromhex(m.payload["data_hex"])) for m in raw] and raw
        assert len(msgs[f"/limb{n}/joint_states"]) == sum(1 for j in expected_joint_states(src) if j[0] == n) > 500
        states = [m for m in src.messages["/zenoh/state"] if m.payload["key"] == f"sea/limb{n}/state"]
        assert [b.seq for *_, b in msgs[f"/limb{n}/state"]] == [m.payload["seq"] for m in states]
    rosout = Counter(m[3].name for m in msgs["/rosout"])
    assert {"limb1/controller", "limb2/controller", "driver1", "driver2"} <= set(rosout)
    assert rosout["limb1/controller"] + rosout["limb2/controller"] == len(src.messages["/log/events"])
    diag = {m[3].status[0].name for m in msgs["/diagnostics"]}
    assert {"limb1/driver1", "limb2/driver2", "limb1/edge", "limb2/edge", "recorder"} <= diag


@pytest.mark.skipif(NODE is None, reason="node is not installed (the independent reader is JS)")
@pytest.mark.skipif(not (JS / "node_modules" / "@foxglove" / "rosmsg2-serialization").is_dir(),
                    reason="npm packages missing: run `npm ci` in tests/js (scripts/test does)")
def test_mcap_core_and_foxglove_decode_the_bag(one_limb):
    src, bag, directory = one_limb
    res = subprocess.run([NODE, str(JS / "check_ros2_bag.mjs"), str(directory / f"{directory.name}_0.mcap")],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    report = json.loads(res.stdout)
    total = sum(len(v) for v in bag["messages"].values())
    assert (report["profile"], report["errors"]) == ("ros2", [])
    assert report["indexedMessages"] == report["streamMessages"] == total
    assert set(report["channels"]) == set(bag["messages"])
    for topic, ch in report["channels"].items():
        assert (ch["schemaEncoding"], ch["messageEncoding"], ch["undecodable"]) == ("ros2msg", "cdr", 0), ch
        assert ch["messages"] == len(bag["messages"][topic]) and "offered_qos_profiles" in ch["metadata"]
    first_raw = src.messages["/can/raw"][0].payload
    f = report["channels"]["/from_can_bus"]["first"]
    assert (f["id"], bytes(f["data"][:f["dlc"]])) == (first_raw["can_id"], bytes.fromhex(first_raw["data_hex"]))
    last = report["channels"]["/joint_states"]["last"]
    assert last["position"] == list(bag["messages"]["/joint_states"][-1][3].position)
    assert last["name"] == ["hip", "knee"]
