"""A real-time `sea-hil run` watched for stalls, for the benchmarks that run many of them (bench_live, bench_soak).

`watch_run(cmd, out)` starts the command with its progress lines on (no `--quiet`), copies its stderr to
`out/stderr.txt`, and follows the progress: simulated time (`sim`) must keep advancing, and once the controller has
sent its first setpoint, so must the setpoints. If neither advances for `stall_s` while progress lines still come,
or no line at all comes for `silent_s` while the process runs (its main thread is stuck), the session is a stall:
every process of its tree is dumped (`py-spy dump --native` if py-spy is installed: every thread's Python and native
stack, twice, 2 s apart) into `out/stall-dumps.txt`, the tree is ended (SIGTERM: the session's close path, then
SIGKILL) and the outcome says `stalled` instead of raising: one stalled session is a result of the benchmark, not
the end of it. `on_tick(proc)` is called about once a second while the session runs (the soak samples its processes
there).
"""
from __future__ import annotations

import re
import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import psutil

from sea_hil.runtime.processes import end_process

PROGRESS = re.compile(r"sim\s+([\d.]+)/[\d.]+ s .*setpoints (\d+)\s+states (\d+)")


@dataclass
class Outcome:
    status: str                       # ok | failed | stalled
    returncode: int | None
    wall_s: float
    last_progress: str = ""
    dumps: Path | None = None
    stderr_tail: str = ""
    live_url: str | None = None
    notes: list[str] = field(default_factory=list)


class _Follower:
    """Reads the child's stderr in a thread: copies it to a file, keeps the newest progress and the times at which
    simulated time / setpoints last advanced, and the first match of `find` (e.g. the live view's address)."""

    def __init__(self, stream, copy_to: Path, find: re.Pattern[str] | None) -> None:
        self.lock = threading.Lock()
        self.last_line_t = self.advanced_t = time.monotonic()
        self.sim_s, self.setpoints, self.last_progress = -1.0, -1, ""
        self.found: str | None = None
        self.found_event = threading.Event()
        self.tail: list[str] = []
        self._find = find
        self._thread = threading.Thread(target=self._run, args=(stream, copy_to), daemon=True)
        self._thread.start()

    def _run(self, stream, copy_to: Path) -> None:
        with open(copy_to, "w", encoding="utf-8") as f:
            for raw in stream:
                line = raw.decode(errors="replace")
                f.write(line)
                f.flush()
                self._line(line)
        self.found_event.set()   # end of output: nobody waits for a match any more

    def _line(self, line: str) -> None:
        now = time.monotonic()
        with self.lock:
            self.last_line_t = now
            self.tail = (self.tail + [line])[-40:]
            if self._find is not None and self.found is None and (m := self._find.search(line)):
                self.found = m.group(1)
                self.found_event.set()
            if m := PROGRESS.search(line):
                sim_s, sp = float(m.group(1)), int(m.group(2))
                if sim_s > self.sim_s or (sp > self.setpoints and self.setpoints > 0):
                    self.advanced_t = now
                elif self.setpoints <= 0 < sp:
                    self.advanced_t = now
                self.sim_s, self.setpoints, self.last_progress = sim_s, sp, line.strip()

    def join(self, timeout_s: float) -> None:
        self._thread.join(timeout_s)


def py_spy() -> str | None:
    """The py-spy executable beside this interpreter or on PATH, if installed."""
    here = Path(sys.executable).with_name("py-spy")
    return str(here) if here.exists() else shutil.which("py-spy")


def dump_tree(pid: int, path: Path, rounds: int = 2) -> None:
    """Every thread's stack of `pid` and its descendants into `path` (py-spy), `rounds` times."""
    spy = py_spy()
    with open(path, "w", encoding="utf-8") as f:
        if spy is None:
            f.write("py-spy is not installed (pip install py-spy): no stacks, process list only\n")
        for r in range(rounds):
            try:
                procs = [psutil.Process(pid), *psutil.Process(pid).children(recursive=True)]
            except psutil.Error:
                return
            for p in procs:
                try:
                    f.write(f"==== round {r} pid {p.pid} {p.status()} cpu {p.cpu_times()} :: "
                            f"{' '.join(p.cmdline())[:240]}\n")
                except psutil.Error:
                    continue
                f.flush()
                if spy is not None:
                    subprocess.run([spy, "dump", "--native", "--pid", str(p.pid)], stdout=f, stderr=subprocess.STDOUT,
                                   timeout=120, check=False)
            if r + 1 < rounds:
                time.sleep(2.0)


def end_tree(proc: subprocess.Popen, grace_s: float = 20.0) -> None:
    """SIGTERM the process (its close path ends its children), then SIGKILL whatever of the tree is left."""
    try:
        kids = psutil.Process(proc.pid).children(recursive=True)
    except psutil.Error:
        kids = []
    end_process(proc, grace_s)
    for k in kids:
        try:
            k.wait(timeout=5.0)
        except psutil.TimeoutExpired:
            _kill_and_reap(k)
        except psutil.Error:
            pass


def _kill_and_reap(proc: psutil.Process) -> None:
    """SIGKILL, then wait until it is gone: end_tree returns only when the tree no longer runs."""
    try:
        proc.kill()
        proc.wait(timeout=5.0)
    except (psutil.Error, psutil.TimeoutExpired):
        pass   # gone already, or a zombie its (new) parent has not reaped yet


def watch_run(cmd: Sequence[str], out: Path, *, cwd: Path, stall_s: float = 30.0, silent_s: float = 180.0,
              timeout_s: float = 3600.0, find: re.Pattern[str] | None = None,
              on_found: Callable[[str], None] | None = None,
              on_tick: Callable[[subprocess.Popen], None] | None = None, dump_rounds: int = 2) -> Outcome:
    """Run `cmd` (a `sea-hil run` with progress on) until it ends or stalls; see the module docstring. `on_found`
    is called (in this thread, the session running) with the first match of `find` in its stderr."""
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.monotonic()
    with open(out / "stdout.txt", "wb") as stdout:
        proc = subprocess.Popen(list(cmd), cwd=cwd, stdin=subprocess.DEVNULL, stdout=stdout, stderr=subprocess.PIPE)
    fol = _Follower(proc.stderr, out / "stderr.txt", find)
    status, dumps = "ok", None
    try:
        if find is not None and on_found is not None:
            fol.found_event.wait(120.0)
            if fol.found is not None:
                on_found(fol.found)
        while proc.poll() is None:
            try:
                proc.wait(timeout=1.0)
                break
            except subprocess.TimeoutExpired:
                pass
            if on_tick is not None:
                on_tick(proc)
            now = time.monotonic()
            with fol.lock:
                stuck = (now - fol.advanced_t > stall_s and now - fol.last_line_t < stall_s) \
                    or now - fol.last_line_t > silent_s
            if stuck or now - t0 > timeout_s:
                status, dumps = "stalled", out / "stall-dumps.txt"
                dump_tree(proc.pid, dumps, dump_rounds)
                break
    finally:
        end_tree(proc)
        fol.join(10.0)
    rc = proc.returncode
    if status == "ok" and rc != 0:
        status = "failed"
    tail = "".join(fol.tail)
    if status == "failed" and "did not finish within" in tail:
        status = "stalled"   # the session's own budget caught it first (no dumps)
    return Outcome(status, rc, time.monotonic() - t0, fol.last_progress, dumps, tail[-2000:], fol.found)
