"""The public Python API of sea-hil (listed in docs/api.md; everything else is internal and may change).

- `EmulatedDriver`: the emulated SEA drive firmware and the limb it moves, serving CAN node ids on a bus, in a
  background thread — what a user's own CAN controller talks to (`virtual:` channels in one process, `socketcan:vcan0`).
- `Session`: a whole HIL session as `sea-hil run` runs it (plant, edge and recorder in this process, the remote
  controller in a child process over Zenoh), in real time or in lockstep; its `summary` is `summary.json`.
- `DriveSnapshot`: the latest state of one emulated drive.
- `load_config`, `SeaHilConfig`, `SeaHilError`: configuration and the one exception root.

Both classes are context managers that start on entry and stop cleanly on exit (idempotent `close()`), expose their
counters and the latest drive state, and run in real time or lockstep (`lockstep=True`).
"""
from __future__ import annotations

import tempfile
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import can

from sea_hil.config.loader import load_config
from sea_hil.config.root import SeaHilConfig
from sea_hil.errors import SeaHilError, VerdictError
from sea_hil.input_check import enforce
from sea_hil.runtime.processes import end_process
from sea_hil.session.builder import SessionBuilder
from sea_hil.session.run import RunOptions, run_session

__all__ = ["DriveSnapshot", "EmulatedDriver", "Session"]


def _config(config: SeaHilConfig | str | Path | None) -> SeaHilConfig:
    return config if isinstance(config, SeaHilConfig) else load_config(config)


@dataclass(frozen=True)
class DriveSnapshot:
    """One emulated drive at its latest sample (SI units; joint 1 = hip, joint 2 = knee)."""
    node_id: int
    state: str                          # INIT | RUNNING | FAULT | ESTOP
    flags: int                          # the heartbeat's error flags (docs/can-protocol.md)
    sample_t_s: float                   # the drive's own sample clock
    theta_rad: tuple[float, float]
    omega_rad_s: tuple[float, float]
    deflection_m: tuple[float, float]   # SEA spring deflections
    voltage_v: tuple[float, float]      # the motor voltages it applies


def _snapshot(drivers: dict[int, Any], node_id: int | None) -> DriveSnapshot:
    if node_id is None:
        node_id = next(iter(drivers))
    try:
        drv = drivers[node_id]
    except KeyError as err:
        raise SeaHilError(f"no emulated drive with node id {node_id} (serving {sorted(drivers)})") from err
    fb = drv.feedback()
    return DriveSnapshot(node_id, drv.state.name, int(drv.flags), drv.sample_t_ns * 1e-9, tuple(fb.theta_rad),
                         tuple(fb.omega_rad_s), tuple(fb.delta_m), tuple(drv.voltage_v))


class EmulatedDriver:
    """The emulated drive firmware on `bus` (a spec such as ``"virtual:NAME"`` / ``"socketcan:vcan0"``, or an open
    python-can bus, which stays the caller's), serving `node_ids`. `lockstep=True`: it integrates a sample only once
    the VOLTAGE_CMD answering its feedback arrived (deterministic, as fast as the controller answers); else real time
    at `can.feedback_rate_hz` with the watchdog."""

    def __init__(self, bus: str | can.BusABC = "virtual:sea-hil", node_ids: int | Sequence[int] = 1, *,
                 config: SeaHilConfig | str | Path | None = None, lockstep: bool = False) -> None:
        self.config = _config(config)
        self.node_ids = (node_ids,) if isinstance(node_ids, int) else tuple(node_ids)
        self.lockstep = lockstep
        self._builder = SessionBuilder(self.config, lockstep=lockstep)
        try:
            self._bus = self._builder.bus(bus) if isinstance(bus, str) else bus
            self._plant = self._builder.plant(self._bus, self.node_ids)
        except BaseException:
            self._builder.close()
            raise
        self.channel = bus if isinstance(bus, str) else str(getattr(bus, "channel_info", bus))
        self._started = self._closed = False

    def start(self) -> EmulatedDriver:
        """Start the drive's loop in a background thread (once)."""
        if self._closed:
            raise SeaHilError("this EmulatedDriver is closed")
        if not self._started:
            self._plant.start()
            self._started = True
        return self

    @property
    def running(self) -> bool:
        return self._started and not self._closed

    def snapshot(self, node_id: int | None = None) -> DriveSnapshot:
        """The latest state of drive `node_id` (default: the first served)."""
        return _snapshot(self._plant.drivers, node_id)

    @property
    def counters(self) -> dict[str, int]:
        """ticks, overruns, frames ignored or rejected, send failures, and per drive commands and watchdog trips."""
        st = self._plant.stats
        out = {"ticks": st.ticks, "overruns": st.overruns, "send_failures": st.send_failures,
               "bus_errors": st.bus_errors, "foreign_frames": st.foreign_frames}
        for n, drv in self._plant.drivers.items():
            c = drv.counters
            out.update({f"node{n}_commands": c.commands, f"node{n}_rejected_frames": c.rejected_frames,
                        f"node{n}_watchdog_trips": c.watchdog_trips, f"node{n}_ignored_commands": c.ignored_commands})
        return out

    def close(self) -> None:
        """Stop the loop, join its thread, release the bus it opened. Idempotent."""
        if not self._closed:
            self._closed = True
            self._builder.close()

    def __enter__(self) -> EmulatedDriver:
        return self.start()

    def __exit__(self, *_exc: object) -> None:
        self.close()


class Session:
    """A whole session, as `sea-hil run` runs it: `run()` blocks until the cycles are done and returns the summary
    (`summary.json`); `start()` runs it in a background thread (`wait()` for the summary). Outputs (MCAP recording,
    summary.json, figures) go to `out` (default: a temporary directory removed by `close()`). `close()` before the
    end stops the session early (its controller process is ended; `summary` stays None). `controller="external"`:
    no controller is started, the session waits up to `join_timeout_s` for your own at `endpoint`, exactly as
    `sea-hil run --controller external` (docs/external-controller.md; like it, with the trigger at the controller).
    The config's inputs are checked at construction (ConfigError; `allow_unsafe_start=True` runs it anyway);
    `strict=True`: `run()` and `wait()` raise `VerdictError` (the summary in its `summary`) when the verdict is not
    ok (docs/verdict.md)."""

    def __init__(self, config: SeaHilConfig | str | Path | None = None, *, controller: str = "et", cycles: int = 1,
                 lockstep: bool = True, out: str | Path | None = None, can: str | None = None,
                 progress: bool = False, join_timeout_s: float = 300.0, strict: bool = False,
                 allow_unsafe_start: bool = False) -> None:
        if controller not in ("et", "tt", "external"):
            raise SeaHilError(f"controller must be 'et', 'tt' or 'external', not {controller!r}")
        if cycles < 1:
            raise SeaHilError(f"cycles must be >= 1, not {cycles}")
        self.config = enforce(_config(config), force=allow_unsafe_start)   # ConfigError: docs/verdict.md
        self.strict = strict
        if controller == "external" and self.config.trigger.placement == "edge":
            # as `sea-hil run --controller external`: your controller speaks the documented STATE protocol (every
            # state up, docs/external-controller.md), so the trigger runs at the controller
            trigger = self.config.trigger.model_copy(update={"placement": "controller"})
            self.config = self.config.model_copy(update={"trigger": trigger})
        self._tmp = tempfile.TemporaryDirectory(prefix="sea-hil-session-") if out is None else None
        self.out = Path(out) if out is not None else Path(self._tmp.name) if self._tmp is not None else Path()
        self._opts = RunOptions(controller=controller, cycles=cycles, out=self.out, lockstep=lockstep, can=can,
                                progress=progress, on_nodes=self._on_nodes, join_timeout_s=join_timeout_s,
                                driver_process=False)   # `snapshot` reads the drivers: in this process
        self.summary: dict[str, Any] | None = None
        self.error: BaseException | None = None
        self._parts: tuple[Any, Any, Any] | None = None
        self._ready = threading.Event()
        self._thread: threading.Thread | None = None
        self._closing = False

    def _on_nodes(self, plant: Any, edge: Any, proc: Any) -> None:
        self._parts = (plant, edge, proc)
        self._ready.set()

    def run(self) -> dict[str, Any]:
        """Run the session to its end in this thread; its summary."""
        try:
            self.summary = run_session(self.config, self._opts, log=lambda _msg: None)
            verdict = self.summary.get("verdict") or {}
            if self.strict and verdict.get("status") != "ok":
                raise VerdictError(self.summary, f"verdict {verdict.get('status')}: " + "; ".join(
                    r["message"] for r in verdict.get("reasons", [])))
        except SeaHilError as err:
            if not self._closing:
                self.error = err
                raise
        finally:
            self._ready.set()
        return self.summary or {}

    def start(self) -> Session:
        """Run the session in a background thread (once)."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._run_quietly, name="sea-hil-session", daemon=True)
            self._thread.start()
        return self

    def _run_quietly(self) -> None:
        try:
            self.run()
        except SeaHilError:
            pass                 # kept in `error`, raised by `wait`

    def wait(self, timeout_s: float | None = None) -> dict[str, Any]:
        """Wait for a started session to end; its summary (SeaHilError if it failed or did not end in time)."""
        if self._thread is None:
            raise SeaHilError("the session was not started")
        self._thread.join(timeout_s)
        if self._thread.is_alive():
            raise SeaHilError(f"the session did not end within {timeout_s} s")
        if isinstance(self.error, VerdictError):
            raise self.error
        if self.error is not None:
            raise SeaHilError(f"the session failed: {self.error}") from self.error
        return self.summary or {}

    def wait_until_running(self, timeout_s: float = 60.0) -> bool:
        """Wait until the session's nodes are up (True), or it ended first / the timeout passed (False)."""
        return self._ready.wait(timeout_s) and self._parts is not None

    @property
    def endpoint(self) -> str | None:
        """`controller="external"`: the Zenoh endpoint your controller connects to, once the nodes run (else None);
        the session's config for it is `out/config.toml` (docs/external-controller.md)."""
        proc = self._parts[2] if self._parts is not None else None
        return getattr(proc, "endpoint", None)

    def snapshot(self, node_id: int | None = None) -> DriveSnapshot:
        """The latest state of the session's emulated drive."""
        if self._parts is None:
            raise SeaHilError("the session's nodes are not running yet")
        return _snapshot(self._parts[0].drivers, node_id)

    @property
    def counters(self) -> dict[str, float]:
        """The edge's counters (the fields of its /stats record; docs/recording.md), {} before the nodes run."""
        return {} if self._parts is None else dict(self._parts[1].stats_dict())

    def close(self) -> None:
        """End the session (early if it still runs), join it, remove a temporary output directory. Idempotent."""
        self._closing = True
        if self._thread is not None and self._thread.is_alive():
            self._ready.wait(60.0)        # nodes still being built: stop it once they are
            if self._parts is not None:
                end_process(self._parts[2])   # the controller ends: the session stops, the recording is closed
        if self._thread is not None:
            self._thread.join(120.0)
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    def __enter__(self) -> Session:
        return self.start()

    def __exit__(self, *_exc: object) -> None:
        self.close()
