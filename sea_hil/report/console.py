"""What `sea-hil run` and `sea-hil simulate` print: live progress while a session runs and one short table at the
end (the verdict and its reasons first, then mode, messages and bytes up/down/total and the ratios to TT, tracking
error per joint, latency, warnings, files written).

Rendering only: the numbers come from summary.json as written (read through `field`, which also finds the
timing-derived fields under a `timing` key). Progress is a rich progress bar when its stream is a terminal and one
plain line per update otherwise (logs, CI, pipes), so `sea-hil run --json > summary.json` keeps a clean stdout.
"""
from __future__ import annotations

import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple, TextIO

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from sea_hil.report.completeness import NOT_RECORDED, completeness_lines
from sea_hil.verdict.summary_fields import field, sync_periods

JOINTS = ("hip", "knee")


class ProgressSample(NamedTuple):
    """One progress update of a running session; `str()` is the plain progress line."""
    wall_s: float
    sim_s: float
    lead_in_s: float
    period_s: float
    cycles: int
    setpoints: int
    states: int
    latency_p50_us: float
    waiting: bool = False       # `--controller external`: no controller has joined yet (nothing has started)

    @property
    def total_s(self) -> float:
        return self.lead_in_s + self.period_s * self.cycles

    @property
    def phase(self) -> str:
        if self.waiting:
            return "waiting for controller"
        if self.sim_s < self.lead_in_s:
            return "lead-in"
        cycle = min(int((self.sim_s - self.lead_in_s) // self.period_s) + 1, self.cycles)
        return f"cycle {cycle}/{self.cycles}"

    def __str__(self) -> str:
        if self.waiting:
            return f"[{self.wall_s:6.1f} s] waiting for controller  states {self.states}"
        return (f"[{self.wall_s:6.1f} s] sim {self.sim_s:6.2f}/{self.total_s:.2f} s  {self.phase}  setpoints "
                f"{self.setpoints}  states {self.states}  latency p50 {self.latency_p50_us:.0f} us")


class SessionProgress:
    """Callable progress sink for `run_session(log=...)`: `ProgressSample`s drive a rich bar on a terminal, any
    other line (and every sample off a terminal) is printed as it is. `close()` ends the bar."""

    def __init__(self, stream: TextIO | None = None, *, terminal: bool | None = None) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.terminal = self.stream.isatty() if terminal is None else terminal
        self._progress: Progress | None = None
        self._task: Any = None

    def __call__(self, line: object) -> None:
        if not self.terminal or not isinstance(line, ProgressSample):
            print(line, file=self.stream, flush=True)
            return
        if self._progress is None:
            self._progress = Progress(TextColumn("[bold]{task.description}"), BarColumn(),
                                      TextColumn("sim {task.completed:.2f}/{task.total:.2f} s"),
                                      TextColumn("{task.fields[info]}"), TimeElapsedColumn(),
                                      console=Console(file=self.stream, force_terminal=True), transient=True)
            self._progress.start()
            self._task = self._progress.add_task("session", total=line.total_s, info="")
        self._progress.update(self._task, completed=min(line.sim_s, line.total_s), description=line.phase,
                              info=f"setpoints {line.setpoints}  states {line.states}  "
                                   f"p50 {line.latency_p50_us:.0f} us")

    def close(self) -> None:
        if self._progress is not None:
            self._progress.stop()
            self._progress = None

    def __enter__(self) -> SessionProgress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _messages(summary: Mapping[str, Any], tt_msgs: int | None) -> list[tuple[str, str]]:
    """Messages and bytes per direction and in total; the ratios to TT (which sends a state up and a setpoint down
    every sample: `tt_msgs` samples, else the uplink count, right when the edge publishes every sample)."""
    tx = summary.get("transmissions") or {}   # states up, setpoints (or voltages) down (offline: as a session would)
    up, down = int(tx.get("uplink_msgs", 0)), int(tx.get("downlink_msgs", 0))
    total = int(tx.get("total_msgs", up + down))
    up_b, down_b = int(tx.get("uplink_bytes", 0)), int(tx.get("downlink_bytes", 0))
    tt = up if tt_msgs is None else tt_msgs
    rows = [("messages up / down / total", f"{up} / {down} / {total}"),
            ("bytes up / down / total", f"{up_b} / {down_b} / {int(tx.get('total_bytes', up_b + down_b))}")]
    if tt:
        rows.append(("ratio to TT", f"{down / tt:.3f} ({down} / {tt} samples)"))
        rows.append(("total ratio to TT", f"{total / (2 * tt):.3f} ({total} / {2 * tt} messages)"))
    return rows


def _warnings(summary: Mapping[str, Any]) -> list[str]:
    timing = summary.get("timing") or {}
    edge = {**(timing.get("edge") or {}), **(summary.get("edge") or {})}   # counters and wall-time-derived ones
    out = []
    if not summary.get("lockstep", True):   # lockstep has no deadlines: simulated time waits for every node
        out.append(f"deadline misses: {edge.get('loop_overruns', 0)} edge loop overruns")
        driver = timing.get("driver") or {}
        if driver.get("tick_misses"):   # shown below the verdict's threshold too: nothing silent
            out.append(f"driver tick misses: {driver['tick_misses']} of {driver.get('ticks', 0)}")
        sync = sync_periods(summary)
        if sync is not None and sync[0]:   # the cia402 profile's SYNC producer (the edge), like the tick misses
            out.append(f"SYNC misses: {sync[0]} of {sync[1]} periods")
    per_limb = [(f"{e['limb']}: ", e["link_losses"]) for e in summary.get("limbs") or [] if "link_losses" in e]
    for limb, losses in per_limb or [("", summary.get("link_losses") or {})]:   # several limbs: each its own
        if losses.get("uplink_beyond_model", 0):
            out.append(f"{limb}states lost beyond the uplink model: {losses['uplink_beyond_model']}")
    lost = (summary.get("recording") or {}).get("lost", 0)
    if lost:
        out.append(f"recording lost: {lost} messages")
    drops = {k: edge.get(k, 0) for k in ("uplink_dropped", "downlink_dropped", "seq_lost", "bus_errors")}
    out += [f"{k.replace('_', ' ')}: {v}" for k, v in drops.items() if v]
    out += rejection_warnings(summary)
    saturated = summary.get("saturated_steps", edge.get("saturated_steps", 0))
    if saturated:
        out.append(f"voltage saturated: {saturated} steps")
    return out


def rejection_label(cls: str) -> str:
    """The table's words for a rejection class of summary.json's `rejections` (its /stats counter name)."""
    if cls == "payload_rejected_key":
        return "payloads on the wrong key"
    if cls.startswith("payload_rejected_"):
        return f"malformed payloads ({cls.removeprefix('payload_rejected_')})"
    named = {"epoch_foreign": "foreign-epoch payloads", "epoch_old": "old-epoch payloads"}
    return named.get(cls, cls.replace("_", " "))


def rejection_warnings(summary: Mapping[str, Any]) -> list[str]:
    """One "what: count" per rejection class with a count (summary.json `rejections` and `timing.rejections`;
    older summaries without them: the edge counters they had)."""
    timing = summary.get("timing") or {}
    classes = {**(summary.get("rejections") or {}), **(timing.get("rejections") or {})}
    if not classes:
        edge = {**(timing.get("edge") or {}), **(summary.get("edge") or {})}
        classes = {k: edge.get(k, 0) for k in ("stale_setpoints", "rejected_frames", "rejected_samples")}
    return [f"{rejection_label(k)}: {v}" for k, v in classes.items() if v]
def verdict_rows(summary: Mapping[str, Any]) -> list[tuple[str, str]]:
    """The verdict (summary.json `verdict`, docs/verdict.md) and one row per reason; [] for a summary without one."""
    v = summary.get("verdict")
    if not isinstance(v, Mapping):
        return []
    reasons = v.get("reasons") or []
    status = str(v.get("status", "?"))
    rows = [("verdict", status if not reasons else f"{status.upper()} ({len(reasons)} reason"
                                                     f"{'s' if len(reasons) > 1 else ''})")]
    rows += [(f"  {r.get('severity', '')}: {r.get('code', '')}", str(r.get("message", ""))) for r in reasons]
    return rows


def end_of_run_rows(summary: Mapping[str, Any], files: Sequence[Path] = (), *, command: str = "run",
                    tt_msgs: int | None = None) -> list[tuple[str, str]]:
    """The (what, value) rows of the end-of-run table."""
    ctrl = str(summary.get("controller", "?")).upper() + "-SMC"
    if command == "simulate":
        mode = f"simulate (offline), {ctrl}" + (", quantised" if summary.get("quantised") else "")
    else:
        mode = f"{'lockstep' if summary.get('lockstep') else 'real time'}, {ctrl}, inner loop on " \
               f"{summary.get('inner', 'edge')}"
    lead = field(summary, "lead_in", "duration_s", default=0.0)
    verdict_lines = verdict_rows(summary)
    rows = verdict_lines + [("mode", mode), ("duration", f"{summary.get('duration_s', 0.0):.2f} s" +
                                        (f" (+ {lead:.2f} s lead-in)" if lead else ""))]
    rows += _messages(summary, tt_msgs)
    tracking = summary.get("tracking", {})
    # a recording (it has a completeness block) with nothing of the measured cycle (duration 0: a recorder cut off
    # in the lead-in, or never routed the controller's records): its tracking zeros are not measurements
    untracked = "completeness" in summary and not summary.get("duration_s")
    for j, name in enumerate(JOINTS):
        mx, rms = tracking.get("max_abs_error_rad", [None] * 2)[j], tracking.get("rms_error_rad", [None] * 2)[j]
        if mx is not None:
            rows.append((f"error {name} max / RMS", NOT_RECORDED if untracked else f"{mx:.4f} / {rms:.4f} rad"))
    lat = field(summary, "latency_us", default=None)
    if isinstance(lat, Mapping) and lat.get("p50", -1) >= 0:
        rows.append(("latency p50 / p99", f"{lat['p50'] / 1000:.2f} / {lat.get('p99', 0) / 1000:.2f} ms"))
    limbs = summary.get("limbs", [])
    for e in limbs if len(limbs) > 1 else []:   # several limbs: one row each
        err, lat_e = e["tracking"]["max_abs_error_rad"], e["timing"]["latency_us"]
        rows.append((f"limb {e['limb']} (node {e['node_id']}, {e['bus']})",
                     f"{e['transmissions']['downlink_msgs']} setpoints, max error {err[0]:.4f} / {err[1]:.4f} rad, "
                     f"latency p99 {lat_e['p99'] / 1000:.2f} ms"))
    wall = field(summary, "wall_s", default=None)
    cpu = summary.get("cpu_s")
    for what, value in (("wall time", wall), ("CPU time", cpu)):
        if isinstance(value, (int, float)):
            rows.append((what, f"{value:.1f} s"))
    comp = summary.get("completeness")
    if isinstance(comp, Mapping):   # a recording against the nodes' own counters (sea_hil.report.completeness)
        rows.append(("recording complete", "yes" if comp.get("complete") else
                     "no: " + "; ".join(completeness_lines(comp))))
    rows.append(("warnings", "; ".join(_warnings(summary)) or ("none" if len(verdict_lines) <= 1 else
                                                                   "the verdict's reasons above")))
    if files:
        rows.append(("files", "\n".join(str(f) for f in files)))
    return rows


def print_end_of_run(summary: Mapping[str, Any], files: Sequence[Path] = (), *, command: str = "run",
                     tt_msgs: int | None = None, stream: TextIO | None = None) -> None:
    """Print the end-of-run table (plain box drawing when `stream` is not a terminal)."""
    table = Table(title=f"sea-hil {command}", show_header=False, title_justify="left")
    table.add_column("what", style="bold")
    table.add_column("value")
    for what, value in end_of_run_rows(summary, files, command=command, tt_msgs=tt_msgs):
        table.add_row(what, value)
    Console(file=stream if stream is not None else sys.stdout, width=120).print(table)


def files_in(directory: Path) -> list[Path]:
    """The files a command wrote into `directory` (sorted)."""
    return sorted(p for p in directory.iterdir() if p.is_file()) if directory.is_dir() else []
