"""The secure Zenoh profile as zenoh config settings: mutual TLS and access control by certificate CN.

Pure mapping from `[zenoh.tls]` / `[zenoh.acl]` (sea_hil/config.py) to `{json5 path: value}` pairs that
`sea_hil.protocol.zsession` inserts into a `zenoh.Config`; `check_tls_files` is the only I/O. The ACL is default-deny:

| who (subject)                 | may send to this node (ingress)                         | may receive (egress) |
|-------------------------------|---------------------------------------------------------|----------------------|
| any peer on a TLS link        | `declare_subscriber` on `<prefix>/**`, `put` on `<prefix>/*/stats` | `put` on `<prefix>/**` |
| CN = `acl.controller_cn`      | `put` on `<limb>/setpoint`, `voltage`, `control`, `event` |                      |
| CN = `acl.edge_cn`            | `put` on `<limb>/state`                                 |                      |

Everything else (other puts, deletes, queries, replies, queryables, liveliness) is denied. A TLS link exists only
with a certificate signed by the configured CA (mTLS), so "any peer on a TLS link" means "any node holding a
certificate of this deployment". See docs/security.md.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from sea_hil.config.comms import ZenohAclConfig, ZenohConfig, ZenohTlsConfig
from sea_hil.errors import ConfigError
from sea_hil.protocol.keys import Keys, any_limb, everything

TLS_FILES = ("root_ca_certificate", "certificate", "private_key")
SUBJECT_ANY, SUBJECT_CONTROLLER, SUBJECT_EDGE = "tls-peers", "controller", "edge"


def tls_settings(tls: ZenohTlsConfig) -> dict[str, Any]:
    """`transport/link/tls/*` settings for a node that both listens and connects with the same identity."""
    if not tls.enabled:
        return {}
    base = "transport/link/tls/"
    return {
        base + "root_ca_certificate": tls.root_ca_certificate,
        base + "listen_certificate": tls.certificate,
        base + "listen_private_key": tls.private_key,
        base + "connect_certificate": tls.certificate,
        base + "connect_private_key": tls.private_key,
        base + "enable_mtls": True,
        base + "verify_name_on_connect": tls.verify_name_on_connect,
        base + "close_link_on_expiration": True,
    }


def _rule(rule_id: str, flows: list[str], messages: list[str], key_exprs: list[str]) -> dict[str, Any]:
    return {"id": rule_id, "permission": "allow", "flows": flows, "messages": messages, "key_exprs": key_exprs}


def acl_document(acl: ZenohAclConfig, keys: Keys) -> dict[str, Any]:
    """The zenoh `access_control` object (default deny; see the module table)."""
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": [
            _rule("observe", ["ingress", "egress"], ["declare_subscriber"], [everything(keys.prefix)]),
            _rule("deliver", ["egress"], ["put"], [everything(keys.prefix)]),
            _rule("stats-in", ["ingress"], ["put"], [any_limb(keys.prefix, "stats")]),
            _rule("commands-in", ["ingress"], ["put"], [keys.setpoint, keys.voltage, keys.control, keys.event]),
            _rule("state-in", ["ingress"], ["put"], [keys.state]),
        ],
        "subjects": [
            {"id": SUBJECT_ANY, "link_protocols": ["tls"]},
            {"id": SUBJECT_CONTROLLER, "cert_common_names": [acl.controller_cn]},
            {"id": SUBJECT_EDGE, "cert_common_names": [acl.edge_cn]},
        ],
        "policies": [
            {"id": "authenticated-peers", "rules": ["observe", "deliver", "stats-in"], "subjects": [SUBJECT_ANY]},
            {"id": "controller-commands", "rules": ["commands-in"], "subjects": [SUBJECT_CONTROLLER]},
            {"id": "edge-state", "rules": ["state-in"], "subjects": [SUBJECT_EDGE]},
        ],
    }


def security_settings(z: ZenohConfig) -> dict[str, Any]:
    """All secure-profile settings of a `[zenoh]` section (empty when TLS and ACL are off)."""
    out = tls_settings(z.tls)
    if z.acl.enabled:
        out["access_control"] = acl_document(z.acl, Keys.make(z.prefix, z.limb))
    return out


def check_tls_files(tls: ZenohTlsConfig) -> None:
    """Fail early with a clear `ConfigError` if a configured PEM file is missing or unreadable."""
    if not tls.enabled:
        return
    for name in TLS_FILES:
        path = Path(getattr(tls, name))
        try:
            data = path.read_bytes()
        except OSError as err:
            raise ConfigError(f"zenoh.tls.{name}: cannot read {path}: {err.strerror or err}") from err
        if b"-----BEGIN " not in data:
            raise ConfigError(f"zenoh.tls.{name}: {path} is not a PEM file")
