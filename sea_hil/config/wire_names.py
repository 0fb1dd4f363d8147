"""The names the config accepts for the wire: CAN bus specs (`socketcan:IFNAME`, `virtual:NAME`, `ipc:NAME`,
`udp_multicast:GROUP`) and Zenoh key chunks (a prefix, a limb name). Checked when a config is loaded, and by the
wire layer (`sea_hil.protocol.canbus`, `sea_hil.protocol.keys`) with the same rules."""
from __future__ import annotations

import ipaddress
import re

from sea_hil.errors import ConfigError

INTERFACES = ("socketcan", "virtual", "ipc", "udp_multicast")
_IFNAME = re.compile(r"[A-Za-z0-9_.\-]{1,15}")  # Linux IFNAMSIZ (16) minus the NUL
_IPC_NAME = re.compile(r"[A-Za-z0-9_\-][A-Za-z0-9_.\-]{0,39}")   # one file name, not hidden, short (sun_path)
_USAGE = "expected 'socketcan:IFNAME', 'virtual:NAME', 'ipc:NAME' or 'udp_multicast:GROUP'"


def validate_ipc_channel(channel: str) -> str:
    """An `ipc` channel names a directory (`sea_hil.protocol.ipc_bus.channel_dir`): 1-40 characters of
    A-Z a-z 0-9 _ . -, not starting with '.'."""
    if not isinstance(channel, str) or not _IPC_NAME.fullmatch(channel):
        raise ConfigError(f"bad ipc channel {channel!r}: 1-40 characters of A-Z a-z 0-9 _ . -, not starting "
                          "with '.'")
    return channel


def parse_can_spec(spec: str) -> tuple[str, str]:
    """``"socketcan:vcan0"`` -> ``("socketcan", "vcan0")``; `ConfigError` for anything malformed."""
    if not isinstance(spec, str) or ":" not in spec:
        raise ConfigError(f"bad CAN spec {spec!r}: {_USAGE}")
    interface, _, channel = spec.partition(":")
    if interface not in INTERFACES:
        raise ConfigError(f"bad CAN spec {spec!r}: unknown interface {interface!r}; {_USAGE}")
    if interface == "socketcan" and not _IFNAME.fullmatch(channel):
        raise ConfigError(f"bad CAN spec {spec!r}: {channel!r} is not a network interface name "
                          "(1-15 characters of A-Z a-z 0-9 _ . -)")
    if interface == "virtual" and (not channel or channel != channel.strip()):
        raise ConfigError(f"bad CAN spec {spec!r}: virtual channel name must be non-empty without "
                          "surrounding spaces")
    if interface == "ipc":
        try:
            validate_ipc_channel(channel)
        except ConfigError as err:
            raise ConfigError(f"bad CAN spec {spec!r}: {err}") from err
    if interface == "udp_multicast":
        try:
            group = ipaddress.ip_address(channel)
        except ValueError:
            group = None
        if group is None or not group.is_multicast:
            raise ConfigError(f"bad CAN spec {spec!r}: udp_multicast needs an IPv4/IPv6 multicast group "
                              "address, e.g. udp_multicast:239.74.163.2")
    return interface, channel


_FORBIDDEN = frozenset("*$#?")


def _check_chunk(what: str, chunk: str, full: str) -> None:
    if not chunk:
        raise ConfigError(f"zenoh {what} {full!r} has an empty chunk (leading, trailing or double '/')")
    bad = sorted(set(chunk) & _FORBIDDEN)
    if bad:
        raise ConfigError(f"zenoh {what} {full!r} contains forbidden character(s) {''.join(bad)!r}")
    if any(c.isspace() for c in chunk):
        raise ConfigError(f"zenoh {what} {full!r} contains whitespace")


def validate_prefix(prefix: str) -> str:
    """A prefix is one or more '/'-separated chunks without wildcards (`*`, `$`), `#`, `?` or whitespace."""
    if not isinstance(prefix, str) or not prefix:
        raise ConfigError("zenoh prefix must be a non-empty string")
    for chunk in prefix.split("/"):
        _check_chunk("prefix", chunk, prefix)
    return prefix


def validate_limb(limb: str) -> str:
    """A limb name is exactly one chunk: like a prefix chunk and additionally without '/'."""
    if not isinstance(limb, str) or not limb:
        raise ConfigError("zenoh limb must be a non-empty string")
    if "/" in limb:
        raise ConfigError(f"zenoh limb {limb!r} must not contain '/'")
    _check_chunk("limb", limb, limb)
    return limb
