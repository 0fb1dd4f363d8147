"""The node runtime: the `Node` lifecycle (template loop, idempotent close, context manager), the one stats schema
of every node (checked against its JSON schema), and the session builder (cleanup order, Zenoh from the config)."""
from __future__ import annotations

import json
import uuid

import jsonschema
import pytest

from sea_hil.config.loader import load_config
from sea_hil.protocol.payloads import PayloadCounters
from sea_hil.recorder.schemas import schema_for
from sea_hil.recorder.zenoh_tap import zenoh_record
from sea_hil.runtime.clock import RealTimeClock
from sea_hil.runtime.lockstep import LockstepClock, clock_for
from sea_hil.runtime.node import Node
from sea_hil.session.builder import SessionBuilder
from sea_hil.session.run import RunOptions, controller_config, listen_endpoints
from sea_hil.stats.schema import STATS_JSON_SCHEMA, StatsError, stats_record, validate_stats


class Counter(Node):
    kind = "plant"

    def __init__(self, until: int | None) -> None:
        super().__init__()
        self.until, self.steps, self.closed, self.started = until, 0, 0, 0

    def _on_start(self, duration_s: float | None) -> None:
        self.started += 1

    def _step(self) -> bool:
        self.steps += 1
        if self.until is None:
            self.stop_event.wait(0.001)
            return False
        return True

    def finished(self) -> bool:
        return self.until is not None and self.steps >= self.until

    def _close(self) -> None:
        self.closed += 1

    def _stats(self) -> dict[str, int]:
        return {"steps": self.steps}


def test_node_runs_until_finished_or_given_up_and_closes_once() -> None:
    with Counter(until=5) as node:
        assert node.run() is True and node.steps == 5 and node.started == 1
    assert node.closed == 1
    node.close()
    assert node.closed == 1                       # idempotent
    idle = Counter(until=None)
    assert idle.run(duration_s=0.01) is False     # no progress for the duration: gives up
    idle.start()
    idle.close()                                  # stops and joins the thread `start` made
    assert not idle._thread.is_alive() and idle.closed == 1


def test_stats_record_follows_the_one_schema() -> None:
    validator = jsonschema.Draft202012Validator(STATS_JSON_SCHEMA)
    record = Counter(until=1).stats_record(final=True)
    assert record["node"] == "plant" and record["final"] is True and isinstance(record["t_ns"], int)
    validator.validate(json.loads(json.dumps(record)))
    assert schema_for("/stats") == STATS_JSON_SCHEMA      # the recorder registers the same schema
    for bad in ({"node": "edge", "final": 1, "t_ns": 0}, {"node": "x", "final": True, "t_ns": 0},
                {"node": "edge", "final": True, "t_ns": 0, "x": "text"},
                {"node": "edge", "final": True, "t_ns": 0, "x": True}, {"final": True, "t_ns": 0}):
        with pytest.raises(StatsError):
            validate_stats(bad)
        assert not validator.is_valid(bad)
    with pytest.raises(StatsError, match="reserved"):
        stats_record("edge", {"final": 1})


def test_real_node_records_validate(tmp_path) -> None:
    """Plant, edge and controller records (fresh nodes) pass the JSON schema; so does the recorder's."""
    cfg = load_config(overrides={"can": {"interface": f"virtual:rt-{uuid.uuid4().hex[:8]}"}})
    validator = jsonschema.Draft202012Validator(STATS_JSON_SCHEMA)
    with SessionBuilder(cfg) as b:
        session = b.zenoh(listen=(), connect=())
        nodes = [b.plant(b.bus(), (1,)), b.edge(b.bus(), session, 1), b.controller(session, "et"),
                 b.recorder(None, session)]
        for node in nodes:
            validator.validate(json.loads(json.dumps(node.stats_record(final=True))))
        assert nodes[1].stats_record()["uplink_msgs"] == 0


def test_recorder_refuses_stats_breaking_the_schema() -> None:
    pc = PayloadCounters()
    good = {"node": "controller", "final": True, "t_ns": 1, "states_handled": 3}
    assert zenoh_record("sea/limb1/stats", json.dumps(good).encode(), pc) == ("/stats", good)
    with pytest.raises(StatsError):
        zenoh_record("sea/limb1/stats", json.dumps({"node": "controller", "final": "yes", "t_ns": 1}).encode(), pc)


def test_clock_choice() -> None:
    assert isinstance(clock_for(False), RealTimeClock) and isinstance(clock_for(True), LockstepClock)
    assert SessionBuilder(load_config(), lockstep=True).clock.name == "lockstep"


def test_builder_closes_in_reverse_order_once() -> None:
    order: list[str] = []
    b = SessionBuilder(load_config())
    b.callback(order.append, "first")
    node = b.add(Counter(until=1))
    b.callback(order.append, "last")
    with b:
        pass
    b.close()
    assert order == ["last", "first"] and node.closed == 1


def test_run_uses_the_zenoh_section_for_both_processes() -> None:
    """`sea-hil run`: the host listens on a loopback endpoint of the configured transport; the controller child
    gets the same [zenoh] section (mode, TLS, ACL) but connects there and listens nowhere."""
    cfg = load_config(overrides={"zenoh": {"mode": "client", "listen": ["tcp/127.0.0.1:7447"]}})
    (ep,) = listen_endpoints(cfg, RunOptions())
    assert ep.startswith("tcp/127.0.0.1:")
    assert listen_endpoints(cfg, RunOptions(listen=("tcp/127.0.0.1:9",))) == ("tcp/127.0.0.1:9",)
    child = controller_config(cfg, ep)
    assert (child.zenoh.mode, child.zenoh.listen, child.zenoh.connect) == ("client", (), (ep,))
    assert child.zenoh.tls == cfg.zenoh.tls and child.zenoh.acl == cfg.zenoh.acl
    tls = {"enabled": True, "root_ca_certificate": "ca.pem", "certificate": "c.pem", "private_key": "k.pem"}
    secure = load_config(overrides={"zenoh": {"tls": tls}})
    assert listen_endpoints(secure, RunOptions())[0].startswith("tls/127.0.0.1:")
