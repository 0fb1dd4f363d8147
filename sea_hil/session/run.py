"""`sea-hil run`: a full session on one machine.

This process hosts the plant (driver node) and the edge on the CAN bus (embedded `virtual` bus by default, or
`socketcan:vcan0`), plus the recorder; the remote controller runs in a separate process and reaches them over Zenoh
(this process listens on a free loopback port, the controller connects). When the controller has finished its
cycles everything is stopped, the MCAP file is closed and summary.json and figures are written from it.
"""
from __future__ import annotations

import json
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from sea_hil.controller.edge import EdgeNode
from sea_hil.plant_emulator.node import PlantNode
from sea_hil.protocol.canbus import open_bus
from sea_hil.config import SeaHilConfig, config_to_toml
from sea_hil.errors import SeaHilError
from sea_hil.recorder.node import RecorderNode
from sea_hil.recorder.process import RecorderProcess
from sea_hil.recorder.writer import read_session
from sea_hil.protocol.zsession import free_tcp_port, make_config, open_session
from sea_hil.session.processes import end_process
from sea_hil.report.writer import write_report_figures
from sea_hil.report.session_summary import session_summary
from sea_hil.report.summary import write_summary


@dataclass(frozen=True)
class RunOptions:
    controller: str = "et"
    cycles: int = 1
    out: Path = Path("runs/latest")
    lockstep: bool = False
    inner: str = "edge"
    can: str | None = None
    node_id: int = 1
    listen: tuple[str, ...] = ()
    progress: bool = True
    seed: int | None = None


def _controller_cmd(opts: RunOptions, cfg_path: Path, endpoint: str) -> list[str]:
    cmd = [sys.executable, "-m", "sea_hil.cli", "controller", "--config", str(cfg_path), "--connect", endpoint,
           "--controller", opts.controller, "--cycles", str(opts.cycles), "--inner", opts.inner]
    return cmd + (["--lockstep"] if opts.lockstep else [])


def run_session(cfg: SeaHilConfig, opts: RunOptions, log: Callable[[str], None] = print) -> dict[str, Any]:
    opts.out.mkdir(parents=True, exist_ok=True)
    cfg_path = opts.out / "config.toml"
    cfg_path.write_text(config_to_toml(cfg), encoding="utf-8")
    endpoint = opts.listen[0] if opts.listen else f"tcp/127.0.0.1:{free_tcp_port()}"
    spec = opts.can or cfg.can.interface
    session = open_session(make_config(listen=[endpoint, *opts.listen[1:]]))
    t0 = time.monotonic()
    # the controller's start-up (interpreter, imports, Zenoh) overlaps the set-up of the nodes here
    proc = subprocess.Popen(_controller_cmd(opts, cfg_path, endpoint), stdin=subprocess.DEVNULL)
    try:
        _host_nodes(cfg, opts, spec, session, proc, t0, log)
    finally:
        end_process(proc)
        session.close()
    wall_s = time.monotonic() - t0
    data = read_session(opts.out / "session.mcap")
    summary = session_summary(data, opts.controller)
    summary["timing"]["wall_s"] = wall_s
    summary["lockstep"] = opts.lockstep
    summary["inner"] = opts.inner
    write_summary(opts.out / "summary.json", summary)
    write_report_figures(data, opts.out)
    return summary


def _host_nodes(cfg: SeaHilConfig, opts: RunOptions, spec: str, session: Any, proc: subprocess.Popen[bytes],
                t0: float, log: Callable[[str], None]) -> None:
    """Plant, edge and recorder in this process until the controller process `proc` has finished its cycles."""
    buses = [open_bus(spec), open_bus(spec), open_bus(spec)]
    # decode + JSON + MCAP off this GIL; in real time on idle CPU time only (SCHED_IDLE)
    rec = RecorderProcess(opts.out / "session.mcap", cfg.record, idle=not opts.lockstep)
    rec.write_session_header(cfg, seed=cfg.link.seed, argv=sys.argv,
                             extra={"controller": opts.controller, "lockstep": str(opts.lockstep),
                                    "inner": opts.inner, "can": spec})
    recorder = RecorderNode(rec, session, cfg.zenoh.prefix, buses[2], tap_batch_s=0.002)
    plant = PlantNode(cfg, buses[0], (opts.node_id,), lockstep=opts.lockstep)
    edge = EdgeNode(cfg, buses[1], session, opts.node_id, inner=opts.inner, lockstep=opts.lockstep)
    threads = [threading.Thread(target=plant.run, name="plant", daemon=True),
               threading.Thread(target=edge.run, name="edge", daemon=True)]
    recorder.start()
    for t in threads:
        t.start()
    period_s = cfg.trajectory.period_s
    budget_s = 60.0 + 3.0 * period_s * opts.cycles
    try:
        while True:
            try:
                proc.wait(timeout=1.0)      # returns as soon as the controller has finished
                break
            except subprocess.TimeoutExpired:
                pass
            now = time.monotonic() - t0
            if now > budget_s:
                raise SeaHilError(f"session did not finish within {budget_s:.0f} s")
            if opts.progress:
                c = edge.counters
                lat = c.latency.to_dict()
                sim_s = edge._sample_t_ns * 1e-9
                log(f"[{now:6.1f} s] sim {sim_s:6.2f} s  cycle {min(int(sim_s // period_s) + 1, opts.cycles)}/"
                    f"{opts.cycles}  setpoints {c.setpoints + c.voltages}  states {c.states_sent}  "
                    f"latency p50 {lat['p50'] * 1e6 if lat['count'] else 0:.0f} us")
        if proc.returncode != 0:
            raise SeaHilError(f"controller process exited with status {proc.returncode}")
    finally:
        end_process(proc)
        plant.stop()
        edge.stop_event.set()
        for t in threads:
            t.join(timeout=10)
        recorder.stop()
        now_ns = time.time_ns()
        rec.record("/stats", now_ns, now_ns, {**edge.stats_dict(), "final": True})
        rec.add_metadata("sea-hil.edge", {k: str(v) for k, v in edge.stats_dict().items()})
        rec.close(final_stats={"plant_overruns": plant.stats.overruns, "plant_ticks": plant.stats.ticks,
                               **recorder.counters()})
        edge.close()
        for b in buses:
            b.shutdown()


def print_summary(summary: dict[str, Any]) -> None:
    print(json.dumps(summary, indent=2, sort_keys=True))
