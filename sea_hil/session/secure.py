"""`sea-hil run --secure`: the session's two Zenoh identities (docs/security.md, "sea-hil run --secure").

This process (plant, edge and recorder share one Zenoh session) presents the edge's certificate, the controller
child the controller's: mutual TLS on every link, and the default-deny ACL, so only the controller's CN may command
and only the edge's CN may publish the state. Certificates come from `--certs DIR` (the files `sea-hil certs --out
DIR` writes: ca.pem, edge.pem/.key, controller.pem/.key) or are generated into `OUT/certs` (a throwaway CA, plus
the recorder's and an intruder's certificates for external tools and demonstrations). The ACL's common names are
read from the two certificates, so any CA's certificates under those file names work.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlsplit

from cryptography import x509
from cryptography.x509.oid import NameOID

from sea_hil.config.root import SeaHilConfig
from sea_hil.errors import ConfigError
from sea_hil.protocol.zcerts import DEFAULT_NODES, make_certs

HOST_NODE, CONTROLLER_NODE = "edge", "controller"


@dataclass(frozen=True)
class SecureProfile:
    host: SeaHilConfig          # this process: the edge's identity
    controller: SeaHilConfig    # the controller child: the controller's identity
    certs: Path


def _common_name(pem: Path) -> str:
    try:
        cert = x509.load_pem_x509_certificate(pem.read_bytes())
    except (OSError, ValueError) as err:
        raise ConfigError(f"--secure: cannot read certificate {pem}: {err}") from err
    names = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    if not names:
        raise ConfigError(f"--secure: certificate {pem} has no common name (the ACL identifies nodes by it)")
    return str(names[0].value)


def _hosts(listen: tuple[str, ...]) -> tuple[str, ...]:
    """The hosts of `--listen` endpoints (`tls/HOST:PORT`), as subjectAltNames for generated certificates."""
    out = []
    for ep in listen:
        proto, _, addr = ep.partition("/")
        if proto != "tls":
            raise ConfigError(f"--secure: listen endpoint {ep!r} must be tls/HOST:PORT")
        host = urlsplit("//" + addr).hostname
        if host:
            out.append(host)
    return tuple(out)


def _identity(cfg: SeaHilConfig, certs: Path, node: str, cns: dict[str, str]) -> SeaHilConfig:
    tls = {"enabled": True, "root_ca_certificate": str(certs / "ca.pem"), "certificate": str(certs / f"{node}.pem"),
           "private_key": str(certs / f"{node}.key"), "verify_name_on_connect": True}
    acl = {"enabled": True, "controller_cn": cns[CONTROLLER_NODE], "edge_cn": cns[HOST_NODE]}
    z = type(cfg.zenoh).model_validate({**cfg.zenoh.model_dump(), "tls": tls, "acl": acl, "listen": (), "connect": ()})
    return cfg.model_copy(update={"zenoh": z})


def secure_profile(cfg: SeaHilConfig, out: Path, certs: Path | None, listen: tuple[str, ...] = ()) -> SecureProfile:
    """The host's and the controller child's configs: `cfg` with mutual TLS and the ACL, each its own identity."""
    hosts = _hosts(listen)
    if certs is None:
        certs = out / "certs"
        make_certs(certs, DEFAULT_NODES, hosts=hosts)
    certs = certs.resolve()
    for name in ("ca.pem", *(f"{n}.{ext}" for n in (HOST_NODE, CONTROLLER_NODE) for ext in ("pem", "key"))):
        if not (certs / name).is_file():
            raise ConfigError(f"--certs {certs}: {name} missing (generate the set with `sea-hil certs --out DIR`)")
    cns = {n: _common_name(certs / f"{n}.pem") for n in (HOST_NODE, CONTROLLER_NODE)}
    if cns[HOST_NODE] == cns[CONTROLLER_NODE]:
        raise ConfigError(f"--secure: edge and controller certificates share the CN {cns[HOST_NODE]!r}")
    return SecureProfile(_identity(cfg, certs, HOST_NODE, cns), _identity(cfg, certs, CONTROLLER_NODE, cns), certs)
