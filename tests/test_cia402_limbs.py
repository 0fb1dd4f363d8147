"""Several limbs in the cia402 profile (sea_hil/session/limbs.py): a (hip, knee) pair per limb, one limb per bus
(each edge is its bus's SYNC producer), each limb named by its hip node; what is not built is refused with one line
before anything starts."""
from __future__ import annotations

import pytest

from sea_hil.cli import main
from sea_hil.config.loader import load_config
from sea_hil.errors import ConfigError
from sea_hil.session.limbs import limb_config, session_limbs


def _cfg(**can: object):
    return load_config(overrides={"can": {"profile": "cia402", **can}})


def test_limbs_get_their_pair_and_a_bus_each() -> None:
    cfg = _cfg(cia402={"node_ids": [1, 2, 3, 4]}, interface="virtual:legs")
    limbs = session_limbs(cfg, 2)
    assert [(limb.name, limb.node_id, limb.bus) for limb in limbs] == \
        [("limb1", 1, "virtual:legs0"), ("limb2", 3, "virtual:legs1")]
    assert [limb_config(cfg, limb).can.cia402.node_ids for limb in limbs] == [(1, 2), (3, 4)]
    assert session_limbs(_cfg(), None)[0].node_id == 1


def test_what_is_not_built_is_refused_in_one_line() -> None:
    with pytest.raises(ConfigError, match=r"1 \(hip, knee\) pair\(s\) \[1, 2\] for 2 limb\(s\).*\[1, 2, 3, 4\]"):
        session_limbs(_cfg(), 2)
    shared = load_config(overrides={"can": {"profile": "cia402", "cia402": {"node_ids": [1, 2, 3, 4]}},
                                    "limbs": [{"name": "left", "node_id": 1}, {"name": "right", "node_id": 3}]})
    with pytest.raises(ConfigError, match="limbs left, right share CAN bus virtual:sea-hil; one limb per bus"):
        session_limbs(shared)
    with pytest.raises(ConfigError, match=r"at 2000 Hz need 149\.\d % of the 1000000 bit/s bus"):
        session_limbs(_cfg(feedback_rate_hz=2000.0))


def test_run_refuses_before_starting_anything(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", "--can-profile", "cia402", "--lockstep", "--limbs", "2", "--no-figures", "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "one pair per limb" in err, err
