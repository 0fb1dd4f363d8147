"""`sea-hil run`'s drivers as processes of their own (`[timing] driver_process`, real time only; docs/timing.md).

Why (issue 33): in one process the driver's 1 kHz schedule, the edge (the cia402 profile's SYNC producer), Zenoh's
callbacks and the recorder taps take turns at one GIL, so a driver tick waits for whichever of them holds it. Here
each driver (`PlantNode`, or `Cia402PlantNode` for the cia402 profile; one per bus, or one for the merged buses of
`[timing] merge_buses`) is a `sea-hil plant` child, the standalone node of the compose topology, and the edge and
the recorder tap stay in the session process, joined to it by a bus that crosses processes: the embedded
`virtual:NAME` bus (one process's) becomes `ipc:<token>-NAME` (protocol/ipc_bus.py: lossless, one host, no set-up),
SocketCAN, ipc and udp_multicast buses are used as given.

`DriverProcess` is the driver's handle for the session (the `Node` calls `sea_hil.session.limb_nodes` makes:
`start`, `stop`, `join`, `close`, `stats`): the child is spawned at once with `--hold` (its start-up, imports and
compiled kernels, overlaps the session's own), `start()` sends it the go line, `stop()` is SIGTERM (the child stops
its loop and prints its result: `--json`, its final counters), `join()` reads that result into `stats` (ticks,
overruns: the recording's `plant_ticks` / `plant_overruns`), `close()` ends it whatever happened
(`sea_hil.runtime.processes.end_process`). The child dies with this process (`spawn_child`, and the end of its
stdin) and has a session of its own, so a terminal's Ctrl-C reaches only this process, which stops it in order
(driver before recorder tap: the tap records every frame the driver sent).
"""
from __future__ import annotations

import json
import logging
import secrets
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sea_hil.config.loader import config_to_toml
from sea_hil.config.root import SeaHilConfig
from sea_hil.config.wire_names import parse_can_spec
from sea_hil.errors import ConfigError, SeaHilError
from sea_hil.runtime.processes import end_process, spawn_child
from sea_hil.session.limbs import Limb

log = logging.getLogger("sea_hil.session")
RESULT_TIMEOUT_S = 30.0   # a stopped driver child prints its result within this (else it is ended without one)


def session_token() -> str:
    """A fresh channel prefix for this session's ipc buses (other sessions on the host share the directory)."""
    return f"run-{secrets.token_hex(4)}"


def process_bus(spec: str, token: str) -> str:
    """The bus a driver process and this process share for `spec` (module docstring): `virtual:NAME` ->
    `ipc:<token>-NAME`, anything else as given."""
    interface, channel = parse_can_spec(spec)
    if interface != "virtual":
        return spec
    out = f"ipc:{token}-{channel}"
    parse_can_spec(out)   # e.g. a channel name grown past the ipc limit
    return out


def process_limbs(cfg: SeaHilConfig, limbs: tuple[Limb, ...], token: str) -> tuple[Limb, ...]:
    """`limbs` on buses that cross processes (`process_bus`); `ConfigError` for what one process's model needs (the
    bus-timing model of `[can] emulate_bitrate` is one process's timeline)."""
    if cfg.can.emulate_bitrate:
        raise ConfigError("[timing] driver_process needs [can] emulate_bitrate = false: the bus-timing model is one "
                          "process's timeline (set driver_process = false, or --no-driver-process, to use it)")
    return tuple(Limb(limb.name, limb.node_id, process_bus(limb.bus, token)) for limb in limbs)


@dataclass
class DriverStats:
    """The child's final counters as the session reads them (`LimbNodes.final_stats`)."""

    ticks: int = 0
    overruns: int = 0


def plant_command(config_path: Path, routes: tuple[tuple[int, str], ...]) -> list[str]:
    """`sea-hil plant` of one driver: its config, its node ids and their buses (one `--can` for one bus, else one
    per `--node`: a merged bus in the child), `--hold --json`."""
    buses = list(dict.fromkeys(spec for _, spec in routes))
    cans = buses if len(buses) == 1 else [spec for _, spec in routes]
    cmd = [sys.executable, "-m", "sea_hil.cli", "plant", "--config", str(config_path), "--hold", "--json"]
    for spec in cans:
        cmd += ["--can", spec]
    for node_id, _ in routes:
        cmd += ["--node", str(node_id)]
    return cmd


class DriverProcess:
    """One driver in a `sea-hil plant` child (module docstring). `routes`: (node id, bus spec) it serves; the
    cia402 profile: the limb's (hip, knee) node ids, on one bus."""

    kind = "plant"

    def __init__(self, cfg: SeaHilConfig, config_path: Path, routes: tuple[tuple[int, str], ...]) -> None:
        config_path.write_text(config_to_toml(cfg.model_copy(update={"limbs": ()})), encoding="utf-8")
        self.routes = routes
        self.stats: DriverStats | None = None    # set by `join` from the child's result
        self.result: dict[str, Any] | None = None
        self.proc = spawn_child(plant_command(config_path, routes), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                text=True, start_new_session=True)
        self._started = False

    @property
    def pid(self) -> int:
        return self.proc.pid

    def start(self) -> None:
        """The go line: the child's schedule starts."""
        assert self.proc.stdin is not None
        try:
            self.proc.stdin.write("go\n")
            self.proc.stdin.flush()
        except (BrokenPipeError, OSError) as err:   # it died during its start-up: `check` says how
            log.warning("driver process %d did not take its start: %s", self.proc.pid, err)
        self._started = True

    def check(self) -> None:
        """`SeaHilError` if the child has ended while the session runs."""
        code = self.proc.poll()
        if code is not None:
            raise SeaHilError(f"driver process ({self.describe()}) exited with status {code} during the session")

    def describe(self) -> str:
        return ", ".join(f"node {n} on {spec}" for n, spec in self.routes)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()   # `sea-hil plant`: SIGTERM stops its loop, then it prints its result

    def join(self, timeout_s: float | None = None) -> None:
        """Wait for the stopped child and read its result into `stats` (None when it gave none)."""
        if self.stats is not None or not self._started:
            return
        try:
            self.proc.wait(timeout=RESULT_TIMEOUT_S if timeout_s is None else timeout_s)
        except subprocess.TimeoutExpired:
            log.warning("driver process %d gave no result within %.0f s: ended", self.proc.pid, RESULT_TIMEOUT_S)
            end_process(self.proc)
            return
        assert self.proc.stdout is not None
        lines = [ln for ln in self.proc.stdout.read().splitlines() if ln.startswith("{")]
        if not lines:
            log.warning("driver process %d ended (status %s) without its result", self.proc.pid,
                        self.proc.returncode)
            return
        self.result = json.loads(lines[-1])
        counters = self.result["counters"]
        self.stats = DriverStats(int(counters["ticks"]), int(counters["overruns"]))

    def close(self) -> None:
        """End the child (SIGTERM, bounded wait, SIGKILL) and release its pipes. Idempotent."""
        end_process(self.proc)
        for pipe in (self.proc.stdin, self.proc.stdout):
            if pipe is not None:
                try:
                    pipe.close()
                except OSError:
                    pass
