"""Stamps of the closed loop's stages, installed in every process of a `sea-hil run` by `latency_stages.py` (through a
`sitecustomize` on PYTHONPATH), never by the product: `zenoh.open` returns a session proxy whose publishers stamp
each `put` (before and after) and whose subscriber callbacks stamp their entry, and `PayloadCounters.try_decode`
stamps each decode. A callback that is C code (the former newest-only subscriber's `SimpleQueue.put`) is left as it is
(a Python frame in zenoh's thread would cost what it does not), so that stage then ends at the decode. Each stamp is (monotonic ns, kind, key, payload bytes, thread native id, thread CPU ns); the process writes its
stamps to `$SEA_HIL_STAGES_DIR/<pid>.pkl` at exit. Payloads are matched across processes by their bytes (one host,
one CLOCK_MONOTONIC). Works on any checkout whose sessions open Zenoh through `zenoh.open`.

`SEA_HIL_STAGES_PROBE=1` also declares, per state/setpoint subscription, a probe subscriber that runs directly in
zenoh's receiving thread (`indirect=False`): when the product's callback is indirect (a Python thread of
zenoh-python's), the probe's stamp is the arrival in zenoh's own thread.
"""
from __future__ import annotations

import atexit
import os
import pickle
import threading
import time
import types
from pathlib import Path
from typing import Any

Stamp = tuple[int, str, str, bytes, int, int]
_STAMPS: list[Stamp] = []
_HOT_KEYS = ("state", "setpoint", "voltage")
_PUT_KEYS = (*_HOT_KEYS, "event")     # the controller's tracking record follows its setpoint


def _hot(key: str, keys: tuple[str, ...] = _HOT_KEYS) -> bool:
    return str(key).rsplit("/", 1)[-1] in keys


class _Publisher:
    def __init__(self, pub: Any, key: str) -> None:
        self._pub, self._key = pub, key

    def put(self, payload: Any, *args: Any, **kw: Any) -> Any:
        if not _hot(self._key, _PUT_KEYS):
            return self._pub.put(payload, *args, **kw)
        t0, c0 = time.monotonic_ns(), time.thread_time_ns()
        out = self._pub.put(payload, *args, **kw)
        t1 = time.monotonic_ns()
        tid = threading.get_native_id()
        data = bytes(payload)
        _STAMPS.append((t0, "put0", self._key, data, tid, c0))
        _STAMPS.append((t1, "put1", self._key, data, tid, time.thread_time_ns()))
        return out

    def __getattr__(self, name: str) -> Any:
        return getattr(self._pub, name)


def _wrap_handler(zenoh: Any, key: str, handler: Any) -> Any:
    if not _hot(key):
        return handler
    if isinstance(handler, zenoh.handlers.Callback):
        if isinstance(handler.callback, types.BuiltinMethodType):   # C (SimpleQueue.put): no Python frame to add
            return handler
        inner, indirect, kind = handler.callback, handler.indirect, "cb_direct" if not handler.indirect else "cb"
    elif callable(handler):
        inner, indirect, kind = handler, True, "cb"
    else:       # a channel: its receiver stamps nothing here (try_decode does)
        return handler

    def stamped(sample: Any) -> Any:
        t = time.monotonic_ns()
        _STAMPS.append((t, kind, key, sample.payload.to_bytes(), threading.get_native_id(), time.thread_time_ns()))
        return inner(sample)
    return zenoh.handlers.Callback(stamped, indirect=indirect)


class _Session:
    def __init__(self, zenoh: Any, session: Any) -> None:
        self._z, self._s = zenoh, session
        self._probes: list[Any] = []

    def declare_publisher(self, key: Any, *args: Any, **kw: Any) -> Any:
        return _Publisher(self._s.declare_publisher(key, *args, **kw), str(key))

    def declare_subscriber(self, key: Any, handler: Any = None, *args: Any, **kw: Any) -> Any:
        if handler is None:
            return self._s.declare_subscriber(key, *args, **kw)
        if os.environ.get("SEA_HIL_STAGES_PROBE") == "1" and _hot(str(key)):
            def probe(sample: Any, key: str = str(key)) -> None:
                _STAMPS.append((time.monotonic_ns(), "probe", key, sample.payload.to_bytes(),
                                threading.get_native_id(), time.thread_time_ns()))
            self._probes.append(self._s.declare_subscriber(key, self._z.handlers.Callback(probe, indirect=False)))
        return self._s.declare_subscriber(key, _wrap_handler(self._z, str(key), handler), *args, **kw)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._s, name)


def install(out_dir: str) -> None:
    import zenoh

    from sea_hil.protocol import payloads

    real_open = zenoh.open

    def open_(*args: Any, **kw: Any) -> Any:
        return _Session(zenoh, real_open(*args, **kw))
    zenoh.open = open_

    real_try = payloads.PayloadCounters.try_decode

    def try_decode(self: Any, data: Any, *args: Any, **kw: Any) -> Any:
        _STAMPS.append((time.monotonic_ns(), "decode", "", bytes(data), threading.get_native_id(),
                        time.thread_time_ns()))
        return real_try(self, data, *args, **kw)
    counters: Any = payloads.PayloadCounters    # patched for the study only
    counters.try_decode = try_decode

    def dump() -> None:
        Path(out_dir, f"{os.getpid()}.pkl").write_bytes(pickle.dumps(
            {"pid": os.getpid(), "argv": list(__import__("sys").argv), "stamps": list(_STAMPS)}))
    atexit.register(dump)
