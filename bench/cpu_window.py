"""One real-time `sea-hil run` measured over a steady-state window: CPU per thread and process between two /proc
snapshots, and the limb-samples integrated in between (bench/bench_cpu_per_sample.py documents the method)."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from collections import defaultdict
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import psutil

from bench.studies.cpu_profile import finish_record, start_record
from sea_hil.runtime.processes import end_process

PROGRESS = re.compile(r"sim\s+([\d.]+)/[\d.]+ s .*setpoints (\d+)\s+states (\d+)")
PYSPY_TID = re.compile(r'^Thread (\d+) \([^)]*\): "([^"]*)"', re.M)
CLK_TCK = os.sysconf("SC_CLK_TCK")
FEEDBACK_RATE_HZ = 1000.0   # [can] feedback_rate_hz of the default config: one limb-sample per executed tick


@dataclass
class WindowResult:
    limbs: int
    load_avg: float
    samples: int                 # limb-samples in the window
    cpu_s: dict[str, float]      # thread group -> CPU s in the window (user + system)
    sys_s: dict[str, float]      # thread group -> system CPU s in the window (kernel: futex, wakeups, pipes)
    ticks: int = 0               # whole session (summary.json), loaded
    misses: int = 0
    hot: str = ""
    recorded: dict[str, int] | None = None   # whole session: what the recording holds vs what was sent
    complete: bool | None = None   # whole session: summary.json `completeness.complete` (every limb's channels)

    def recorder_us(self) -> float:
        """CPU per limb-sample of the recorder: its child process plus the session's recorder tap threads."""
        return sum(self.per_sample_us(g) for g in self.cpu_s if g.startswith("recorder") or "recorder tap" in g)

    def lost(self) -> int | None:
        """Frames not in the recording though sent (None when not known: session ended early, several limbs)."""
        r = self.recorded
        if not r or "commands_sent" not in r or self.limbs != 1:   # the edge's metadata is one limb's
            return None
        # as bench/bench_soak.py counts (docs/reliability.md): feedback against 3 x (driver ticks + 1), commands
        # against the edge's VOLTAGE_CMDs; `can_frames_missed` (seq gaps) is not a loss count (a watchdog episode,
        # where the edge answers no sample, shows as a gap)
        return (r["recorder_dropped_ops"] + r["dropped"] + r["write_errors"] + r["can_rejected"]
                + abs(r["commands_sent"] - r["/can/command"]) + abs(3 * (self.ticks + 1) - r["/can/feedback"])
                + abs(r["can_frames"] - r["/can/raw"]))

    def child_session_us(self) -> float | None:
        """The recorder child's CPU per limb-sample over the whole session, by its own count (`recorder_cpu_s`: from
        its first message to its close, so also what it caught up on after the window; a SCHED_IDLE child on a
        loaded host gets little CPU in the window), per classic-CAN limb-sample (3 `/can/feedback` messages)."""
        r = self.recorded
        if not r or "recorder_cpu_us" not in r or not r["/can/feedback"]:
            return None
        return r["recorder_cpu_us"] / (r["/can/feedback"] / 3)

    def per_sample_us(self, group: str) -> float:
        return 1e6 * self.cpu_s.get(group, 0.0) / max(self.samples, 1)

    def total_us(self) -> float:
        return 1e6 * sum(self.cpu_s.values()) / max(self.samples, 1)


def recorded_counts(path: Path) -> dict[str, int]:
    """From a finished session file's metadata (summary section, no message read): the recorder's counts per
    channel and of frames missed / rejected / dropped, and (one limb) the edge's VOLTAGE_CMDs sent
    (`commands_sent + arrival_commands`)."""
    from mcap.reader import make_reader
    with open(path, "rb") as f:
        meta = {m.name: dict(m.metadata) for m in make_reader(f).iter_metadata()}
    final = meta.get("sea-hil.final", {})
    out = {k: int(final.get(k, 0)) for k in ("can_frames", "can_frames_missed", "can_rejected",
                                                "recorder_dropped_ops", "dropped", "write_errors")}
    out.update({t: int(final.get(f"messages.{t}", 0)) for t in ("/can/raw", "/can/feedback", "/can/command")})
    if "recorder_cpu_s" in final:   # the recorder child's own CPU count, start-up excluded (sea_hil/recorder/process.py)
        out["recorder_cpu_us"] = round(1e6 * float(final["recorder_cpu_s"]))
    edge = meta.get("sea-hil.edge")
    if edge and "commands_sent" in edge:
        out["commands_sent"] = int(edge["commands_sent"]) + int(edge.get("arrival_commands", 0))
    return out


def _task_cpu_s(pid: int) -> dict[int, tuple[float, float]]:
    """tid -> (utime, stime) in s of every thread of `pid` (/proc/<pid>/task/<tid>/stat)."""
    out: dict[int, tuple[float, float]] = {}
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            stat = (task / "stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2:].split()
        out[int(task.name)] = (int(fields[11]) / CLK_TCK, int(fields[12]) / CLK_TCK)
    return out


def _role(cmdline: list[str]) -> str:
    text = " ".join(cmdline)
    if "sea_hil.recorder" in text:
        return "recorder child"
    if " controller" in text:
        return "controllers"
    if " plant " in f"{text} ":
        return "driver process"
    return "other child"


def _roles(root: psutil.Process) -> dict[int, str]:
    """pid -> role of the session process and of each child whose command line can be read now."""
    roles = {root.pid: "session"}
    try:
        kids = root.children(recursive=True)
    except psutil.Error:
        return roles
    for p in kids:
        try:
            if cmd := p.cmdline():
                roles[p.pid] = _role(cmd)
        except psutil.Error:
            continue
    return roles


def snapshot(root: psutil.Process) -> dict[tuple[int, int], tuple[float, float]]:
    """(pid, tid) -> (user, system) CPU s of every thread of the tree under `root`."""
    pids = [root.pid]
    try:
        pids += [p.pid for p in root.children(recursive=True)]
    except psutil.Error:
        pass
    return {(pid, tid): cpu for pid in pids for tid, cpu in _task_cpu_s(pid).items()}


def thread_names(pid: int, tries: int = 3) -> tuple[dict[int, str], bool]:
    """(tid -> Python thread name from `py-spy dump --nonblocking`, retried: on a loaded machine a dump can fail;
    else the OS thread name `/proc/<pid>/task/<tid>/comm`, which a Python thread shares with its process; True if
    py-spy named them)."""
    names: dict[int, str] = {}
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            names[int(task.name)] = (task / "comm").read_text().strip()
        except OSError:
            continue
    for _ in range(tries):
        try:
            out = subprocess.run([str(Path(sys.executable).with_name("py-spy")), "dump", "--nonblocking", "--pid",
                                  str(pid)], capture_output=True, text=True, timeout=30)
        except (OSError, subprocess.TimeoutExpired):
            continue
        found = {int(tid): name for tid, name in PYSPY_TID.findall(out.stdout)}
        if found:
            return {**names, **found}, True
    return {tid: f"{name} (py-spy named no thread)" for tid, name in names.items()}, False


def merge_names(old: dict[int, str] | None, new: tuple[dict[int, str], bool]) -> dict[int, str]:
    """Names of one process from two dumps: py-spy's names win over the OS names of a failed dump."""
    names, named = new
    if old is None:
        return names
    return {**names, **old} if not named else {**old, **names}


def group_of(role: str, name: str) -> str:
    low = name.lower()
    if role == "session":
        if low.startswith(("plant", "driver")):
            return "session: driver (plant node)"
        if low.startswith("edge"):
            return "session: edge(s)"
        if low.startswith(("rec-", "recorder")):
            return f"session: {name} (recorder tap)"
        if low == "mainthread":
            return "session: main thread"
        return "session: zenoh runtime" if re.match(r"(rx|tx|net|acc|app)-\d+$", low) else f"session: {name}"
    if re.match(r"(rx|tx|net|acc|app)-\d+$", low):
        return f"{role}: zenoh runtime"
    return f"{role}: {name}"


class _Progress:
    """Follows the progress lines on the child's stderr: the newest (sim s, setpoints) and an event per line."""

    def __init__(self, stream) -> None:
        self.cond = threading.Condition()
        self.n, self.sim_s, self.setpoints = 0, 0.0, 0
        self.first_setpoint_t: float | None = None
        self.tail: list[str] = []
        threading.Thread(target=self._run, args=(stream,), daemon=True).start()

    def _run(self, stream) -> None:
        for raw in stream:
            line = raw.decode(errors="replace")
            self.tail = (self.tail + [line])[-15:]
            if m := PROGRESS.search(line):
                with self.cond:
                    self.n, self.sim_s, self.setpoints = self.n + 1, float(m.group(1)), int(m.group(2))
                    if self.setpoints > 0 and self.first_setpoint_t is None:
                        self.first_setpoint_t = time.monotonic()
                    self.cond.notify_all()
        with self.cond:
            self.n = -1
            self.cond.notify_all()

    def _moved_on(self, seen: int) -> bool:
        return self.n != seen

    def next_line(self, after_t: float, proc: subprocess.Popen) -> float:
        """Wait for the first progress line after monotonic time `after_t` (and, first, a setpoint); its sim s."""
        with self.cond:
            while True:
                seen = self.n
                if seen < 0 or proc.poll() is not None:
                    raise RuntimeError("session ended before the window closed (lengthen --cycles or shorten "
                                       "it); its last lines:\n" + "".join(self.tail))
                if self.first_setpoint_t is not None and time.monotonic() >= after_t:
                    self.cond.wait_for(partial(self._moved_on, seen))
                    if self.n < 0:
                        continue
                    return self.sim_s
                self.cond.wait(timeout=0.2)


def measure(limbs: int, warm_s: float, window_s: float, extra: list[str], profile: bool = False,
            sea_hil: str | None = None, tries: int = 2, end_after: bool = False) -> WindowResult:
    """One session (`sea_hil`: the `sea-hil` executable, default this interpreter's) measured over its window; a
    session that fails (a loaded machine can make one miss its budget) is reported and run once more. `end_after`:
    kill the session's process tree right after the window instead of waiting for its end (its SCHED_IDLE recorder
    catches up only on idle CPU time, minutes on a loaded machine); then no summary, so no tick counts."""
    for k in range(tries):
        try:
            return _measure(limbs, warm_s, window_s, extra, profile, sea_hil, end_after)
        except RuntimeError as err:
            if k == tries - 1:
                raise
            print(f"(session failed, run again: {err})", file=sys.stderr, flush=True)
    raise AssertionError("unreachable")


def _kill_tree(root: psutil.Process) -> None:
    """SIGKILL the session and every process under it, each by its pid."""
    try:
        procs = [*root.children(recursive=True), root]
    except psutil.Error:
        procs = [root]
    for p in procs:
        try:
            p.kill()
        except psutil.Error:
            pass


def _measure(limbs: int, warm_s: float, window_s: float, extra: list[str], profile: bool,
             sea_hil: str | None, end_after: bool = False) -> WindowResult:
    with tempfile.TemporaryDirectory(prefix="sea-hil-cpu-") as tmp:
        out = Path(tmp) / "run"
        cmd = [sea_hil or str(Path(sys.executable).with_name("sea-hil")), "run", "--limbs", str(limbs), "--cycles", "1",
               "--out", str(out), *extra]
        load = os.getloadavg()[0]
        # run in the temporary directory: the session's children (`python -m sea_hil...`: controllers, the recorder
        # process) put their working directory first on sys.path, and from a checkout's root an A/B's other
        # checkout would run this checkout's children
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, cwd=tmp)
        try:
            root = psutil.Process(proc.pid)
            prog = _Progress(proc.stderr)
            prog.next_line(0.0, proc)   # the first setpoint
            assert prog.first_setpoint_t is not None
            sim_a = prog.next_line(prog.first_setpoint_t + warm_s, proc)
            a, t_a = snapshot(root), time.monotonic()
            names = {pid: thread_names(pid)[0] for pid in {pid for pid, _ in a}}   # threads ending in the window
            roles_a = _roles(root)
            spy = None
            if profile:
                spy = start_record(proc.pid, window_s, Path(tmp))
            sim_b = prog.next_line(t_a + window_s, proc)
            b = snapshot(root)
            for pid in {pid for pid, _ in b}:
                names[pid] = merge_names(names.get(pid), thread_names(pid))
            roles = {**roles_a, **_roles(root)}
            hot = ""
            if spy is not None:
                hot = finish_record(spy)
            if end_after:
                _kill_tree(root)
                proc.wait(timeout=60)
            rc = 0 if end_after else proc.wait(timeout=600)
        finally:
            if proc.poll() is None:
                end_process(proc)
        if rc != 0:
            raise RuntimeError(f"sea-hil run exited with {rc}")
        summary = {"timing": {"driver": {}}} if end_after else json.loads((out / "summary.json").read_text())
        recorded = None if end_after else recorded_counts(out / "session.mcap")
    groups: dict[str, float] = defaultdict(float)
    system: dict[str, float] = defaultdict(float)
    for (pid, tid), (user, kern) in b.items():
        g = group_of(roles.get(pid, "other child"), names.get(pid, {}).get(tid, "?"))
        user_a, kern_a = a.get((pid, tid), (0.0, 0.0))
        groups[g] += user + kern - user_a - kern_a
        system[g] += kern - kern_a
    drv = summary["timing"]["driver"]
    samples = int(round((sim_b - sim_a) * FEEDBACK_RATE_HZ)) * limbs
    return WindowResult(limbs, load, samples, dict(groups), dict(system), drv.get("ticks", 0), drv.get("tick_misses", 0), hot,
                        recorded, summary.get("completeness", {}).get("complete"))
