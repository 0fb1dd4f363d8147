"""The hot spots of a running session process: `py-spy record --nonblocking --threads -f raw` over a window, folded
into the top functions by own samples (the leaf frame) per thread group (bench/bench_cpu_per_sample.py --profile).

Only samples holding the GIL count (`--gil`: the Python work; a thread waiting on a lock or the bus holds none).
py-spy names a thread in `record` output by its Python ident only, so a thread's group is the first frame of its
stacks that belongs to a known node (plant node, edge, recorder tap, Zenoh subscriber callback)."""
from __future__ import annotations

import re
import subprocess
import sys
from collections import Counter, defaultdict
from dataclasses import dataclass
from pathlib import Path

RATE_HZ = 200
TOP = 12
GROUPS = (("plant_emulator/", "driver (plant node)"), ("controller/edge", "edge(s)"),
          ("recorder/", "recorder tap"), ("zsession.py", "zenoh callbacks"), ("session/run.py", "main thread"))


@dataclass
class Recording:
    proc: subprocess.Popen
    path: Path


def start_record(pid: int, duration_s: float, tmp: Path) -> Recording:
    path = tmp / "py-spy.txt"
    cmd = [str(Path(sys.executable).with_name("py-spy")), "record", "--nonblocking", "--gil", "--threads", "-f", "raw",
           "-r", str(RATE_HZ), "-d", str(max(1, int(duration_s))), "-o", str(path), "-p", str(pid)]
    return Recording(subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL), path)


def _group(frames: list[str]) -> str:
    for frame in frames:
        for needle, group in GROUPS:
            if needle in frame:
                return group
    return "other"


def fold(text: str) -> dict[str, Counter[str]]:
    """thread group -> Counter(leaf function -> samples) from py-spy's raw (collapsed) output."""
    by_thread: dict[str, list[tuple[list[str], int]]] = defaultdict(list)
    for line in text.splitlines():
        stack, _, count = line.rpartition(" ")
        if not stack or not count.isdigit():
            continue
        frames = stack.split(";")
        thread = next((f for f in frames if f.startswith("thread (")), "thread (?)")
        py = [f for f in frames if not f.startswith(("thread (", "process "))]
        if py:
            by_thread[thread].append((py, int(count)))
    out: dict[str, Counter[str]] = defaultdict(Counter)
    for stacks in by_thread.values():
        group = _group([f for py, _ in stacks for f in py])
        for py, n in stacks:
            out[group][re.sub(r":\d+\)$", ")", py[-1])] += n   # per function, not per line
    return out


def finish_record(rec: Recording) -> str:
    """Wait for the recording; the folded top functions as printable lines."""
    try:
        rec.proc.wait(timeout=120)
    except subprocess.TimeoutExpired:
        rec.proc.kill()
        rec.proc.wait()
    if not rec.path.exists():
        return "    (py-spy recorded nothing)"
    folded = fold(rec.path.read_text())
    lines: list[str] = []
    for group, counts in sorted(folded.items(), key=lambda kv: -sum(kv[1].values())):
        total = sum(counts.values())
        lines.append(f"    {group}: {total} samples at {RATE_HZ} Hz")
        lines += [f"      {100 * n / total:5.1f} %  {fn}" for fn, n in counts.most_common(TOP)]
    return "\n".join(lines)
