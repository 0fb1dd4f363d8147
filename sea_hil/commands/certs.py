"""`sea-hil certs --out DIR`: the CLI of `sea_hil.protocol.zcerts` (a throwaway CA and per-node TLS certificates
for the secure Zenoh profile; see that module and docs/security.md).
"""
from __future__ import annotations

import argparse
from pathlib import Path

from sea_hil.errors import ConfigError
from sea_hil.protocol.zcerts import DEFAULT_NODES, make_certs


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("certs", help="generate a throwaway CA and per-node TLS certificates (secure profile)",
                       description="Write ca.pem and, per node, NAME.pem, NAME.key and the config overlay "
                                   "NAME.toml (CN sea-hil-NAME). See docs/security.md.")
    _add_args(p)
    p.set_defaults(func=_main)


def _add_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", required=True, type=Path, help="directory for the PEM files and node profiles")
    p.add_argument("--node", action="append", default=[], metavar="NAME",
                   help=f"node to issue a certificate for (repeatable; default: {', '.join(DEFAULT_NODES)})")
    p.add_argument("--host", action="append", default=[], metavar="NAME_OR_IP",
                   help="extra subjectAltName for every node certificate (repeatable), e.g. edge.lan or 10.0.0.2")
    p.add_argument("--days", type=int, default=30, help="validity in days (default 30)")
    p.add_argument("--no-acl", action="store_true", help="write node profiles with [zenoh.acl] enabled = false")


def _main(args: argparse.Namespace) -> int:
    if args.days < 1:
        raise ConfigError("certs: --days must be >= 1")
    certs = make_certs(args.out, tuple(args.node) or DEFAULT_NODES, hosts=tuple(args.host), valid_days=args.days,
                       acl=not args.no_acl)
    print(f"CA: {certs.ca_certificate}")
    for nc in certs.nodes.values():
        print(f"{nc.node}: CN={nc.common_name} cert={nc.certificate} key={nc.private_key} profile={nc.profile}")
    return 0


if __name__ == "__main__":  # `python -m sea_hil.commands.certs --out DIR` works without registering in sea_hil/cli.py
    import sys

    _parser = argparse.ArgumentParser(prog="sea-hil certs")
    _add_args(_parser)
    try:
        sys.exit(_main(_parser.parse_args()))
    except ConfigError as _err:
        print(f"sea-hil certs: error: {_err}", file=sys.stderr)
        sys.exit(2)
