"""Secure Zenoh profile (docs/security.md): mutual TLS + access control by certificate CN.

Throwaway certificates are generated in tmp_path. The edge listens on tls/127.0.0.1:<free port> with mTLS and the
default-deny ACL; the authorised controller's setpoint/voltage puts reach it, an authenticated intruder's are
denied (it may still observe), and peers without a certificate of the deployment (no client cert, a rogue CA
claiming the controller's CN, plain TCP) never get a link. Every run with `acl` off is the control showing the
same intruder *would* get through, so the assertions can fail. Ordering barriers, not sleeps: an intruder's denied
puts are followed on the same link by an allowed put, and waited for.
"""
from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from contextlib import ExitStack
from pathlib import Path
from typing import Any, TypeVar

import pytest
import zenoh
from paper_scheme import paper

from sea_hil.commands.certs import register
from sea_hil.config.comms import ZenohConfig
from sea_hil.config.loader import load_config
from sea_hil.errors import ConfigError
from sea_hil.protocol.can_assembly import FeedbackAssembler
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import FEEDBACK_PARTS, VoltageCmd
from sea_hil.protocol.keys import Keys
from sea_hil.protocol.payloads import SetpointPayload, TriggerReason, VoltagePayload, encode
from sea_hil.protocol.zcerts import CertSet, make_certs, node_cn
from sea_hil.protocol.zsecurity import acl_document, security_settings
from sea_hil.protocol.zsession import free_tcp_port, make_config, open_session, session_config

DEADLINE_S = 20.0
KEYS = Keys.make("sea", "limb1")
T = TypeVar("T")


@pytest.fixture(scope="module")
def certs(tmp_path_factory: pytest.TempPathFactory) -> CertSet:
    return make_certs(tmp_path_factory.mktemp("pki"))


@pytest.fixture(scope="module")
def rogue(tmp_path_factory: pytest.TempPathFactory) -> CertSet:
    """Another CA issuing a certificate with the controller's CN: the identity is right, the signer is not."""
    return make_certs(tmp_path_factory.mktemp("rogue"), ("controller",), ca_name="rogue CA")


def _tls(certs: CertSet, node: str, ca: CertSet | None = None) -> dict[str, Any]:
    n = (ca or certs).nodes[node]
    return {"enabled": True, "root_ca_certificate": str(certs.ca_certificate), "certificate": str(n.certificate),
            "private_key": str(n.private_key)}


def _zcfg(certs: CertSet, node: str, *, listen: tuple[str, ...] = (), connect: tuple[str, ...] = (),
          acl: bool = False, signer: CertSet | None = None) -> ZenohConfig:
    return ZenohConfig.model_validate({"listen": listen, "connect": connect, "tls": _tls(certs, node, signer),
                                       "acl": {"enabled": acl}})


def _until(cond: Callable[[], T], what: str) -> T:
    end = time.monotonic() + DEADLINE_S
    while time.monotonic() < end:
        got = cond()
        if got:
            return got
        time.sleep(0.001)  # polling pause only; the condition is what we wait for
    pytest.fail(f"timed out waiting for {what}")


def _open(stack: ExitStack, cfg: ZenohConfig | zenoh.Config) -> zenoh.Session:
    s = open_session(cfg)
    stack.callback(s.close)
    return s


def _outsiders(stack: ExitStack, certs: CertSet, rogue: CertSet, ep: str) -> dict[str, zenoh.Session]:
    """Peers that hold no certificate of this deployment."""
    port = ep.rsplit(":", 1)[1]
    no_cert = make_config(connect=[ep], settings={"transport/link/tls/root_ca_certificate": str(certs.ca_certificate)})
    return {"nocert": _open(stack, no_cert),
            "rogue": _open(stack, _zcfg(certs, "controller", connect=(ep,), signer=rogue)),
            "plain": _open(stack, make_config(connect=[f"tcp/127.0.0.1:{port}"]))}


def _matched(session: zenoh.Session, *keys: str) -> dict[str, zenoh.Publisher]:
    """Publishers on `keys`, once each knows a matching remote subscriber (so a put is really sent, not dropped)."""
    pubs = {k: session.declare_publisher(k) for k in keys}
    for k, pub in pubs.items():
        _until(lambda pub=pub: pub.matching_status.matching, f"a subscriber of {k} known to the publisher")
    return pubs


def _drain(sub: zenoh.Subscriber, into: list[bytes]) -> list[bytes]:
    while (s := sub.try_recv()) is not None:
        into.append(s.payload.to_bytes())
    return into


# ---- pure mapping and configuration ---------------------------------------------------------------------------------
def test_acl_document_only_controller_commands() -> None:
    doc = acl_document(_zcfg_plain_acl().acl, KEYS)
    assert doc["default_permission"] == "deny"
    assert all(r["permission"] == "allow" for r in doc["rules"])  # default deny + allow-only: no precedence puzzles
    subjects = {s["id"]: s for s in doc["subjects"]}
    assert subjects["controller"] == {"id": "controller", "cert_common_names": [node_cn("controller")]}
    for key in (KEYS.setpoint, KEYS.voltage):
        granting = {r["id"] for r in doc["rules"] if "put" in r["messages"] and "ingress" in r["flows"]
                    and any(zenoh.KeyExpr(k).includes(zenoh.KeyExpr(key)) for k in r["key_exprs"])}
        assert [s for p in doc["policies"] if granting & set(p["rules"]) for s in p["subjects"]] == ["controller"]


def _zcfg_plain_acl() -> ZenohConfig:
    return ZenohConfig.model_validate({"tls": {"enabled": True, "root_ca_certificate": "ca.pem",
                                               "certificate": "c.pem", "private_key": "c.key"},
                                       "acl": {"enabled": True}})


def test_security_settings_off_by_default() -> None:
    assert security_settings(ZenohConfig()) == {}
    s = security_settings(_zcfg_plain_acl())
    assert s["transport/link/tls/enable_mtls"] is True and s["access_control"]["enabled"] is True


@pytest.mark.parametrize("zenoh_over, match", [
    ({"acl": {"enabled": True}}, "acl needs tls"),
    ({"tls": {"enabled": True}}, "not set"),
    ({"tls": {"enabled": True, "root_ca_certificate": "a", "certificate": "b", "private_key": "c"},
      "listen": ["tcp/127.0.0.1:7447"]}, "must be tls/"),
])
def test_bad_secure_config_is_config_error(zenoh_over: dict[str, Any], match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        load_config(overrides={"zenoh": zenoh_over})


def test_missing_pem_is_config_error(certs: CertSet, tmp_path: Path) -> None:
    bad = ZenohConfig.model_validate({"tls": {**_tls(certs, "edge"), "private_key": str(tmp_path / "none.key")}})
    with pytest.raises(ConfigError, match="private_key"):
        session_config(bad)
    (tmp_path / "junk.pem").write_text("not a certificate")
    with pytest.raises(ConfigError, match="not a PEM"):
        session_config(ZenohConfig.model_validate({"tls": {**_tls(certs, "edge"),
                                                           "certificate": str(tmp_path / "junk.pem")}}))


def test_shipped_profiles_load(certs: CertSet, monkeypatch: pytest.MonkeyPatch) -> None:
    """configs/secure.toml (paths relative to the CWD, here a dir holding certs/) and the generated profiles."""
    repo = Path(__file__).resolve().parents[1]
    monkeypatch.chdir(certs.ca_certificate.parent.parent)
    (Path("certs")).mkdir(exist_ok=True)
    for f in certs.ca_certificate.parent.iterdir():
        (Path("certs") / f.name).write_bytes(f.read_bytes())
    cfg = load_config(repo / "configs" / "secure.toml")
    assert cfg.zenoh.tls.enabled and cfg.zenoh.acl.enabled and cfg.zenoh.tls.certificate == "certs/edge.pem"
    session_config(cfg.zenoh)
    for nc in certs.nodes.values():
        z = load_config(nc.profile).zenoh
        assert Path(z.tls.certificate) == nc.certificate.resolve() and z.acl.controller_cn == node_cn("controller")
        session_config(z)


def test_certs_command_issues_chained_certificates(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from cryptography import x509
    from cryptography.hazmat.primitives.asymmetric import ec
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    args = parser.parse_args(["certs", "--out", str(tmp_path), "--node", "edge", "--node", "controller",
                              "--host", "10.0.0.2", "--host", "edge.lan"])
    assert args.func(args) == 0 and "CN=sea-hil-edge" in capsys.readouterr().out
    ca = x509.load_pem_x509_certificate((tmp_path / "ca.pem").read_bytes())
    for node in ("edge", "controller"):
        cert = x509.load_pem_x509_certificate((tmp_path / f"{node}.pem").read_bytes())
        assert cert.subject.get_attributes_for_oid(x509.NameOID.COMMON_NAME)[0].value == node_cn(node)
        ca.public_key().verify(cert.signature, cert.tbs_certificate_bytes, ec.ECDSA(cert.signature_hash_algorithm))
        san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
        assert "edge.lan" in san.get_values_for_type(x509.DNSName)
        assert {str(a) for a in san.get_values_for_type(x509.IPAddress)} >= {"127.0.0.1", "10.0.0.2"}
        assert (tmp_path / f"{node}.key").stat().st_mode & 0o077 == 0
    with pytest.raises(ConfigError, match="node name"):
        args.func(parser.parse_args(["certs", "--out", str(tmp_path), "--node", "bad name"]))


# ---- message level ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("acl", [True, False], ids=["acl", "control-acl-off"])
def test_only_controller_puts_reach_edge(certs: CertSet, rogue: CertSet, acl: bool) -> None:
    ep = f"tls/127.0.0.1:{free_tcp_port()}"
    with ExitStack() as stack:
        edge = _open(stack, _zcfg(certs, "edge", listen=(ep,), acl=acl))
        subs = {k: edge.declare_subscriber(k, zenoh.handlers.FifoChannel(1024)) for k in (KEYS.setpoint, KEYS.voltage)}
        barrier = edge.declare_subscriber(KEYS.stats, zenoh.handlers.FifoChannel(64))
        ctl = _open(stack, _zcfg(certs, "controller", connect=(ep,)))
        intr = _open(stack, _zcfg(certs, "intruder", connect=(ep,)))
        outsiders = _outsiders(stack, certs, rogue, ep)
        got: dict[str, list[bytes]] = {k: [] for k in subs}
        for k, sub in subs.items():   # the authorised path works (and the subscription has propagated)
            _until(lambda k=k, sub=sub: (ctl.put(k, b"probe"), _drain(sub, got[k]))[1], f"controller probe on {k}")
        seen = intr.declare_subscriber(KEYS.state, zenoh.handlers.FifoChannel(64))
        _until(lambda: (edge.put(KEYS.state, b"s"), seen.try_recv())[1], "the intruder observing state (allowed)")
        attack = _matched(intr, KEYS.setpoint, KEYS.voltage, KEYS.stats)
        for k in subs:
            attack[k].put(b"intruder")
            for s in outsiders.values():
                s.put(k, b"outsider")
        attack[KEYS.stats].put(b"intruder-done")   # allowed; same link and priority, so after its denied puts
        for k in subs:
            ctl.put(k, b"marker")
        _until(lambda: any(s.payload.to_bytes() == b"intruder-done" for s in iter(barrier.try_recv, None)),
               "the intruder's barrier")
        for k, sub in subs.items():
            _until(lambda k=k, sub=sub: b"marker" in _drain(sub, got[k]), f"the controller's marker on {k}")
        peers = {str(z) for z in edge.info.peers_zid()}
        assert peers == {str(ctl.info.zid()), str(intr.info.zid())}
        assert all(not list(s.info.peers_zid()) for s in outsiders.values())
        for k in subs:
            senders = set(got[k]) - {b"probe"}
            assert senders == ({b"marker"} if acl else {b"intruder", b"marker"}), (k, senders)  # no outsider


# ---- the driver ---------------------------------------------------------------------------------------------------
class _CanWatch:
    """Drains an observer bus: the voltage commands sent to the driver and the largest nut speed it reported."""

    def __init__(self, bus: Any) -> None:
        self.bus, self.codec, self.asm = bus, SeaCodec([1]), FeedbackAssembler()
        self.commands: list[tuple[float, float]] = []
        self.max_nut_speed_m_s = 0.0

    def drain(self) -> None:
        while (msg := self.bus.recv(timeout=0)) is not None:
            frame = self.codec.decode(msg)
            if isinstance(frame, VoltageCmd):
                self.commands.append(tuple(frame.voltage_v))
            elif isinstance(frame, FEEDBACK_PARTS) and (fb := self.asm.push(frame)) is not None:
                self.max_nut_speed_m_s = max(self.max_nut_speed_m_s, *map(abs, fb.nut_vel_m_s))


def _start_limb(stack: ExitStack, cfg: Any) -> tuple[Any, zenoh.Session, _CanWatch]:
    """Plant (emulated driver) + EdgeNode (remote inner loop: voltages go straight to CAN) on a virtual bus."""
    from sea_hil.session.builder import SessionBuilder
    session = _open(stack, cfg.zenoh)
    b = stack.enter_context(SessionBuilder(cfg))   # closed first: nodes stop before the session goes
    buses = [b.bus() for _ in range(3)]
    plant = b.plant(buses[0], (1,))
    edge = b.edge(buses[1], session, 1, inner="remote")
    plant.start()
    edge.start()
    return edge, session, _CanWatch(buses[2])


@pytest.mark.parametrize("acl", [True, False], ids=["acl", "control-acl-off"])
def test_intruder_cannot_move_driver(certs: CertSet, acl: bool) -> None:
    port = free_tcp_port()
    ep = f"tls/127.0.0.1:{port}"
    # the remote inner loop (voltages tunnelled to CAN: what an intruder would forge) runs the paper's scheme
    cfg = load_config(overrides=paper({"zenoh": {"listen": [ep], "tls": _tls(certs, "edge"), "acl": {"enabled": acl}},
                                       "can": {"interface": f"virtual:secure-{port}"}}))
    with ExitStack() as stack:
        edge, session, watch = _start_limb(stack, cfg)
        barrier = session.declare_subscriber(KEYS.stats, zenoh.handlers.FifoChannel(64))
        intr = _open(stack, _zcfg(certs, "intruder", connect=(ep,)))
        ctl = _open(stack, _zcfg(certs, "controller", connect=(ep,)))
        seen = intr.declare_subscriber(KEYS.state, zenoh.handlers.RingChannel(1))
        _until(seen.try_recv, "the intruder observing the limb state (allowed; plant, edge and its link are up)")
        attack = _matched(intr, KEYS.voltage, KEYS.setpoint, KEYS.stats)
        for seq in range(1, 21):
            t = time.monotonic_ns()
            attack[KEYS.setpoint].put(encode(SetpointPayload(seq, t, 0, (0.01, 0.01), (0.0, 0.0),
                                                             TriggerReason.INITIAL)))
            attack[KEYS.voltage].put(encode(VoltagePayload(100 + seq, t, 0, (12.0, 12.0))))  # newer than setpoints
        if not acl:   # the control: without the ACL the same intruder drives the limb
            _until(lambda: (watch.drain(), (12.0, 12.0) in watch.commands)[1], "the intruder's voltage on CAN")
            assert edge.core.counters.voltages > 0
            return
        attack[KEYS.stats].put(b"intruder-done")   # allowed, same link: arrives after the denied puts would have
        _until(lambda: any(s.payload.to_bytes() == b"intruder-done" for s in iter(barrier.try_recv, None)),
               "the intruder's barrier")
        fb0 = edge.core.counters.feedback
        _until(lambda: edge.core.counters.feedback >= fb0 + 3, "the edge handling later driver samples")
        watch.drain()
        assert (edge.core.counters.voltages, edge.core.counters.setpoints, edge.core.counters.commands_sent) == (0, 0, 0)
        assert watch.commands == [] and watch.max_nut_speed_m_s == 0.0
        seq = iter(range(1, 1 << 20))

        def command() -> bool:
            ctl.put(KEYS.voltage, encode(VoltagePayload(next(seq), time.monotonic_ns(), 0, (4.0, -4.0))))
            watch.drain()
            return bool(watch.commands) and watch.max_nut_speed_m_s > 0
        _until(command, "the controller's voltage moving the driver")
        assert set(watch.commands) == {(4.0, -4.0)} and edge.core.counters.voltages > 0
