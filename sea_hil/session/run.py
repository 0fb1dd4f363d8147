"""`sea-hil run`: a full session on one machine.

This process hosts the plant (driver node) and the edge on the CAN bus (embedded `virtual` bus by default, or
`socketcan:vcan0`), plus the recorder (real time with `[timing] driver_process`: each driver in a process of its
own, on an `ipc:` bus in place of the embedded one, `sea_hil.session.driver_process`; lockstep never); the remote
controller runs in a separate process and reaches them over Zenoh (this process listens on a free loopback port,
the controller connects). Both use `[zenoh]` of the config (mode,
TLS, ACL); only the endpoints are the session's own (`tls/` when TLS is enabled). `secure=True` (`--secure`)
gives each its own certificate, mutual TLS and the ACL (`sea_hil.session.secure`). When the controller has finished
its cycles everything is stopped (`SessionBuilder`, in reverse order of creation), the MCAP file is closed and
summary.json and figures are written from it.
"""
from __future__ import annotations

import json
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sea_hil.config.loader import config_to_toml
from sea_hil.config.root import SeaHilConfig
from sea_hil.errors import ConfigError, SeaHilError
from sea_hil.live.feed import LiveSpec
from sea_hil.live.link import await_live
from sea_hil.protocol.zsession import free_tcp_port
from sea_hil.recorder.clock import TimeBase
from sea_hil.recorder.process import RecorderProcess
from sea_hil.recorder.reader import read_session
from sea_hil.report.console import ProgressSample
from sea_hil.report.limbs import META_FLOOR
from sea_hil.report.session_summary import session_summary
from sea_hil.report.summary import write_summary
from sea_hil.report.writer import write_report_figures
from sea_hil.runtime.processes import end_process, spawn_child, stop_on_signals
from sea_hil.runtime.realtime import ThreadPolicy, child_priority, host_policy
from sea_hil.runtime.timer_floor import measure_floor
from sea_hil.session import limb_nodes
from sea_hil.session.builder import SessionBuilder
from sea_hil.session.driver_process import process_limbs, session_token
from sea_hil.session.external import OutsideController
from sea_hil.session.limbs import Limb, session_limbs
from sea_hil.session.secure import secure_profile


@dataclass(frozen=True)
class RunOptions:
    controller: str = "et"
    cycles: int = 1
    out: Path = Path("runs/latest")
    lockstep: bool = False
    inner: str = "edge"
    can: str | None = None
    node_id: int = 1
    limbs: int | None = None   # --limbs N: the default limb N times (sea_hil/session/limbs.py); None: [[limbs]] or 1
    listen: tuple[str, ...] = ()
    progress: bool = True
    seed: int | None = None
    join_timeout_s: float = 300.0   # --controller external: wall time allowed for the outside controller to join
    secure: bool = False            # mutual TLS + ACL, the edge's identity here, the controller's in the child
    certs: Path | None = None       # secure: certificates of `sea-hil certs --out DIR`; None: generated in out/certs
    figures: bool = True            # the five PNGs in out (--no-figures: none; `sea-hil report` draws them later)
    on_nodes: Callable[[Any, Any, Any], None] | None = None   # called with (plant, edge, controller) once they run
    driver_process: bool | None = None   # real time: the drivers in processes of their own; None: [timing]


def _controller_cmd(opts: RunOptions, cfg_path: Path) -> list[str]:
    cmd = [sys.executable, "-m", "sea_hil.cli", "controller", "--config", str(cfg_path),
           "--controller", opts.controller, "--cycles", str(opts.cycles), "--inner", opts.inner, "--no-result"]
    return cmd + (["--lockstep"] if opts.lockstep else [])


def listen_endpoints(cfg: SeaHilConfig, opts: RunOptions) -> tuple[str, ...]:
    """The endpoints this process listens on: `--listen`, else a free loopback port (`tls/` with TLS)."""
    if opts.listen:
        return opts.listen
    return (f"{'tls' if cfg.zenoh.tls.enabled else 'tcp'}/127.0.0.1:{free_tcp_port()}",)


def controller_config(cfg: SeaHilConfig, endpoint: str, priority: int | None = None) -> SeaHilConfig:
    """The controller child's config: the same, its `[zenoh]` (mode, TLS, ACL) connected to `endpoint` only; with
    `priority`, its `[timing] controller_priority` (SCHED_FIFO once started: docs/timing.md). Its inputs are not
    checked again (`[verdict] check_inputs = false`): whoever started the session has decided."""
    z = type(cfg.zenoh).model_validate({**cfg.zenoh.model_dump(), "listen": (), "connect": (endpoint,)})
    update: dict[str, Any] = {"zenoh": z, "verdict": cfg.verdict.model_copy(update={"check_inputs": False})}
    if priority is not None:
        update["timing"] = cfg.timing.model_copy(update={"controller_priority": priority})
    return cfg.model_copy(update=update)


def run_session(cfg: SeaHilConfig, opts: RunOptions, log: Callable[..., None] = print) -> dict[str, Any]:
    opts.out.mkdir(parents=True, exist_ok=True)
    # the measured cycles: the edge's trigger records no tracking after them (controller/edge_events.py)
    cfg = cfg.model_copy(update={"sim": cfg.sim.model_copy(update={"cycles": opts.cycles})})
    child_cfg = cfg
    if opts.secure:
        profile = secure_profile(cfg, opts.out, opts.certs, opts.listen)
        cfg, child_cfg = profile.host, profile.controller
    # the live view is served from this process's recorder: a controller started from these files must not
    quiet = _without_live(cfg)
    cfg_path = opts.out / "config.toml"
    cfg_path.write_text(config_to_toml(quiet), encoding="utf-8")
    listen = listen_endpoints(cfg, opts)
    limbs = session_limbs(cfg, opts.limbs, opts.node_id, opts.can)
    if split_drivers(cfg, opts):   # the drivers in processes of their own: buses that cross processes
        limbs = process_limbs(cfg, limbs, session_token())
    if opts.controller == "external" and len(limbs) > 1:
        raise SeaHilError(f"--controller external serves one limb, not {len(limbs)}")
    if opts.inner == "remote" and cfg.trigger.placement == "edge":   # the CLI picks the paper's scheme for it
        raise ConfigError("inner 'remote' computes the voltage from every state: it needs trigger.placement = "
                          "'controller' (--trigger controller --compensation none)")
    # real time: the host's own floor (an empty 1 kHz loop) before anything of the session runs (docs/verdict.md)
    floor = measure_floor(cfg.verdict.floor_measure_s, cfg.timing.realtime_priority) \
        if not opts.lockstep and cfg.verdict.floor_measure_s > 0 else None
    t0 = time.monotonic()
    # SIGTERM/SIGHUP raise `Terminated` here: the builder's close path ends the controller and closes the recording
    with stop_on_signals(), SessionBuilder(cfg, lockstep=opts.lockstep) as b:
        # this process is what the controller connects to: a peer even when the nodes' config says client (a
        # client needs a router; `sea-hil run` has none), with the config's TLS and ACL
        session = b.zenoh(listen=listen, connect=(), mode="peer")
        proc: Any
        if opts.controller == "external":   # no child: wait for an outside controller (sea_hil/session/external.py)
            proc = OutsideController(cfg, opts.cycles, session, endpoint=listen[0], config_path=cfg_path,
                                     lockstep=opts.lockstep, join_timeout_s=opts.join_timeout_s, log=log)
        else:   # the controllers' start-up (interpreter, imports, Zenoh) overlaps the set-up of the nodes here
            procs = []
            base = controller_config(_without_live(child_cfg), listen[0], None if opts.lockstep else
                                     child_priority(cfg.timing))
            for stem, limb_cfg in limb_nodes.controller_configs(base, limbs):
                child_path = opts.out / f"{stem}.toml"
                child_path.write_text(config_to_toml(limb_cfg), encoding="utf-8")
                # the child ends when this process dies (sea_hil/runtime/processes.py)
                procs.append(spawn_child(_controller_cmd(opts, child_path), stdin=subprocess.DEVNULL))
                b.callback(end_process, procs[-1])
            proc = procs[0] if len(procs) == 1 else limb_nodes.ControllerGroup(procs)
        if isinstance(proc, OutsideController):
            b.callback(end_process, proc)
        _host_nodes(b, opts, session, proc, limbs, t0, log, floor)
    wall_s = time.monotonic() - t0
    data = read_session(opts.out / "session.mcap")
    summary = session_summary(data, opts.controller)   # every limb; the file checked, judged
    summary["timing"]["wall_s"] = wall_s
    if b.timelines:   # [can] emulate_bitrate: queueing delay and latency per CAN id (simulated time in lockstep)
        summary["timing"]["can_bus"] = b.bus_timing()
    summary["lockstep"] = opts.lockstep
    summary["inner"] = opts.inner
    write_summary(opts.out / "summary.json", summary)
    if opts.figures:
        write_report_figures(data, opts.out)
    return summary


def split_drivers(cfg: SeaHilConfig, opts: RunOptions) -> bool:
    """True when the session's drivers run in processes of their own: real time and `driver_process` (the option,
    else `[timing] driver_process`, else by profile: cia402 yes, unless `[can] emulate_bitrate` (one process's
    timeline); sea no); lockstep always in one process (its results unchanged bit for bit). Why by profile: the
    cia402 edge is the SYNC producer, and a drive sharing its GIL made it miss 0.5-0.7 % of its SYNCs on an idle
    host, against 0-0.02 % with the drive in its own process; the sea driver owns its tick and gained nothing, at
    25-50 % more CPU (docs/timing.md)."""
    if opts.lockstep:
        return False
    setting = cfg.timing.driver_process if opts.driver_process is None else opts.driver_process
    if setting is None:
        return cfg.can.profile == "cia402" and not cfg.can.emulate_bitrate
    return setting


def _floor_figures(floor: dict[str, Any] | None) -> dict[str, float] | None:
    """The host floor's figures for the live view's verdict (its numbers, as the recording's metadata has them)."""
    if floor is None:
        return None
    return {k: float(v) for k, v in floor.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}


def _without_live(cfg: SeaHilConfig) -> SeaHilConfig:
    return cfg.model_copy(update={"live": cfg.live.model_copy(update={"enabled": False})})


def _host_nodes(b: SessionBuilder, opts: RunOptions, session: Any, proc: Any, limbs: tuple[Limb, ...], t0: float,
                log: Callable[..., None], floor: dict[str, Any] | None = None) -> None:
    """Plant, edge and recorder in this process until the controller `proc` (a child process, or the outside
    controller's watch) has finished its cycles. Closing (the builder's stack, last in first out): the controller
    ends, plant and edge stop, the recorder's taps stop, the edge's final stats are recorded and the MCAP file is
    closed, then buses go."""
    cfg = b.cfg
    split = split_drivers(cfg, opts)
    spec = ", ".join(limb_nodes.buses_of(limbs)) if split else opts.can or cfg.can.interface
    # every bus: plant (or its driver process), edge(s), recorder tap
    nodes = limb_nodes.build_limb_nodes(b, session, limbs, opts.inner, opts.controller,
                                        driver_dir=opts.out if split else None)
    # decode + JSON + MCAP off this GIL; in real time on idle CPU time only (SCHED_IDLE)
    time_base: TimeBase = "sample" if opts.lockstep else "wall"   # log_time clock (docs/recording.md)
    rec = RecorderProcess(opts.out / "session.mcap", cfg.record, idle=not opts.lockstep, time_base=time_base,
                          live=LiveSpec(live=cfg.live, bitrate_bps=cfg.can.bitrate_bps, verdict=cfg.verdict,
                                        lockstep=opts.lockstep, floor=_floor_figures(floor),
                                        limbs={limb.node_id: limb.name for limb in nodes.limbs})
                          if cfg.live.enabled else None)
    b.callback(rec.close)   # idempotent: closes the file if building the nodes failed
    rec.write_session_header(cfg, seed=cfg.link.seed, argv=sys.argv,
                             extra={"controller": opts.controller, "lockstep": str(opts.lockstep),
                                    "inner": opts.inner, "can": spec, "secure": str(opts.secure),
                                    "driver_process": str(split)})
    rec.add_metadata("sea-hil.limbs", nodes.metadata())
    if floor is not None:   # the verdict weighs the driver's tick misses against it (sea_hil/verdict/rules.py)
        rec.add_metadata(META_FLOOR, {k: str(v) for k, v in floor.items()})
    # --foxglove: announce the live view; --foxglove-wait: hold here until a client has subscribed
    waited_s = await_live(rec.live, cfg.live, log) if rec.live is not None else 0.0
    recorders = [b.recorder(rec, session if i == 0 else None, tap, tap_batch_s=0.01, time_base=time_base)
                 for i, tap in enumerate(nodes.taps)]
    edge = nodes.edges[0]
    b.callback(_finish, rec, nodes, recorders, opts.lockstep)
    for p in getattr(proc, "procs", [proc]):
        b.callback(end_process, p)
    for recorder in recorders:
        recorder.start()
    limb_nodes.start(nodes)
    # the drivers elsewhere: this process's threads (edge, Zenoh, taps) take the SCHED_FIFO the driver's process
    # scope would have given them here (undone on close, before the report)
    policy = host_policy(cfg.timing) if split else None
    if policy is not None:
        b.callback(policy.undo)
    if opts.on_nodes is not None:   # the public API's handle on a running session (sea_hil.api.Session)
        opts.on_nodes(nodes.plants[0], edge, proc)
    extra_s = waited_s + (opts.join_timeout_s if opts.controller == "external" else 0.0)
    _wait_for_controller(proc, edge, opts, cfg, t0, extra_s, log, nodes, policy)


def _wait_for_controller(proc: Any, edge: Any, opts: RunOptions, cfg: SeaHilConfig, t0: float, extra_s: float,
                         log: Callable[..., None], nodes: limb_nodes.LimbNodes | None = None,
                         policy: ThreadPolicy | None = None) -> None:
    """Until the controller `proc` has finished (`SeaHilError` past the wall budget, or when a driver process ended
    meanwhile); progress lines once a second; `policy` raises this process's threads started since."""
    period_s = cfg.trajectory.period_s
    budget_s = 60.0 + 3.0 * period_s * opts.cycles + extra_s
    while True:
        try:
            proc.wait(timeout=1.0)      # returns as soon as the controller has finished
            break
        except subprocess.TimeoutExpired:
            pass
        for driver in nodes.driver_processes() if nodes is not None else ():
            driver.check()
        if policy is not None:
            policy.refresh()
        now = time.monotonic() - t0
        if now > budget_s:
            raise SeaHilError(f"session did not finish within {budget_s:.0f} s")
        if opts.progress:
            c = edge.core.counters
            lat = c.latency.to_dict()
            sim_ns, waiting = edge.core.sample_t_ns, False
            if isinstance(proc, OutsideController):   # the session starts when an outside controller answers
                start_ns = proc.watch.first_answer_sample_ns
                waiting = start_ns is None
                sim_ns = 0 if start_ns is None else max(0, sim_ns - start_ns)
            log(ProgressSample(now, sim_ns * 1e-9, cfg.trajectory.lead_in_s, period_s, opts.cycles,
                               c.setpoints + c.voltages, c.states_sent, lat["p50"] * 1e6 if lat["count"] else 0,
                               waiting))
    if proc.returncode != 0:
        raise SeaHilError(f"controller process exited with status {proc.returncode}")


def _finish(rec: RecorderProcess, nodes: limb_nodes.LimbNodes, recorders: list[Any], lockstep: bool) -> None:
    """Stop plants and edges, then the recorder's taps; record each limb's final edge stats (`/stats`, metadata; in
    lockstep at the edge's sample time, the recording's clock), close the MCAP file with the plants' and the first
    recorder's counters (the recorder process counts the CAN frames of every tap)."""
    limb_nodes.stop_and_join(nodes)
    for recorder in recorders:
        recorder.stop()
    for recorder in recorders:
        recorder.join()
    limb_nodes.record_edge_finals(rec, nodes, lockstep)
    for i, driver in enumerate(nodes.driver_processes()):   # a driver process's own result (lateness, sends, ...)
        if driver.result is not None:
            rec.add_metadata("sea-hil.driver" if i == 0 else f"sea-hil.driver.bus{i}",
                             {k: str(v) for k, v in driver.result["counters"].items()})
    rec.close(final_stats={**nodes.final_stats(), **recorders[0].counters()})


def print_summary(summary: dict[str, Any]) -> None:
    print(json.dumps(summary, indent=2, sort_keys=True))
