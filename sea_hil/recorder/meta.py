"""What a session recording says about itself: metadata names, the session/config header and payload encoding.

`write_session_header` works on any recorder with `add_metadata` / `add_attachment` (the in-process
`SessionRecorder` or the `sea_hil.recorder.process.RecorderProcess` proxy).
"""
from __future__ import annotations

import json
import math
import os
import platform
import socket
import sys
import time
from collections.abc import Mapping
from importlib import metadata as importlib_metadata
from typing import Any, Protocol

from sea_hil.config.loader import config_to_toml
from sea_hil.config.root import SeaHilConfig

META_SESSION, META_CONFIG, META_FINAL = "sea-hil.session", "sea-hil.config", "sea-hil.final"
CONFIG_ATTACHMENT = "config.toml"
# `META_SESSION` of the offline session engine's in-memory session (sea_hil/offline/session_engine.py): lockstep, and
# not a recorder's file (no recorder counters, no controller's final record: nothing to check its completeness by)
ENGINE_SOURCE = "offline engine"
ENGINE_SESSION_META = {"lockstep": "True", "source": ENGINE_SOURCE}


def _finite(v: Any) -> Any:
    return None if isinstance(v, float) and not math.isfinite(v) else v


def encode_payload(payload: Mapping[str, Any]) -> bytes:
    """Compact JSON; non-finite floats become null, numpy scalars become Python numbers."""
    def default(o: Any) -> Any:
        if hasattr(o, "item"):
            return _finite(o.item())
        raise TypeError(f"not JSON serialisable: {type(o).__name__}")
    try:
        return json.dumps(payload, separators=(",", ":"), allow_nan=False, default=default).encode()
    except ValueError:
        clean = {k: _finite(v) for k, v in payload.items()}
        return json.dumps(clean, separators=(",", ":"), allow_nan=False, default=default).encode()


def _version(dist: str) -> str:
    try:
        return importlib_metadata.version(dist)
    except importlib_metadata.PackageNotFoundError:
        return "not installed"


def session_metadata(seed: int | None = None, argv: list[str] | None = None) -> dict[str, str]:
    """Host, command line and library versions for the `sea-hil.session` metadata record."""
    return {"python": platform.python_version(), "platform": platform.platform(), "host": socket.gethostname(),
            "pid": str(os.getpid()), "argv": json.dumps(sys.argv if argv is None else argv),
            "seed": "" if seed is None else str(seed), "start_wall_time_ns": str(time.time_ns()),
            "start_monotonic_ns": str(time.monotonic_ns()),
            **{f"version.{d}": _version(d) for d in ("sea-hil", "eclipse-zenoh", "python-can", "mcap", "numpy")}}


def _flatten(prefix: str, d: Mapping[str, Any], out: dict[str, str]) -> dict[str, str]:
    for k, v in d.items():
        if isinstance(v, Mapping):
            _flatten(f"{prefix}{k}.", v, out)
        else:
            out[f"{prefix}{k}"] = json.dumps(v)
    return out



class _HeaderTarget(Protocol):
    def add_metadata(self, name: str, data: Mapping[str, Any]) -> None: ...
    def add_attachment(self, name: str, data: bytes, media_type: str = ..., t_ns: int | None = ...) -> None: ...


def write_session_header(rec: _HeaderTarget, config: SeaHilConfig | None = None, *, seed: int | None = None,
                         argv: list[str] | None = None, extra: Mapping[str, Any] | None = None) -> None:
    """Metadata `sea-hil.session` (+ `extra`), `sea-hil.config` and attachment `config.toml`."""
    rec.add_metadata(META_SESSION, {**session_metadata(seed, argv), **(extra or {})})
    if config is not None:
        rec.add_metadata(META_CONFIG, _flatten("", config.model_dump(mode="json"), {}))
        rec.add_attachment(CONFIG_ATTACHMENT, config_to_toml(config).encode(), "application/toml")

