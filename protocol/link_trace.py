"""Trace-driven link emulation: replay a per-packet delay/loss trace a user measured (or one of the synthetic traces
in configs/traces/, docs/link-traces.md).

A trace is a CSV file with the header `t_s,delay_s,lost` and one row per packet of the measurement: `t_s` the send
time of the packet (seconds, non-decreasing; the first row is the trace's time origin), `delay_s` its one-way delay
(>= 0; ignored when lost), `lost` 0/1 (also `true`/`false`). A message submitted to the emulator at session time t
takes the row of the newest packet sent at or before `t mod duration` (relative to the first row); `duration` is
the span of the trace plus its median packet gap, so a trace shorter than the session is looped seamlessly. The
lookup is pure (no clock, no RNG): the same trace and the same send times give the same delays and losses.
"""
from __future__ import annotations

import bisect
import csv
import functools
import math
import statistics
from dataclasses import dataclass
from itertools import pairwise
from pathlib import Path

from sea_hil.errors import ConfigError

NS_PER_S = 1_000_000_000
COLUMNS = ("t_s", "delay_s", "lost")
_LOST = {"0": False, "1": True, "false": False, "true": True}


@dataclass(frozen=True)
class LinkTrace:
    """Rows of a trace, times relative to its first packet, in integer nanoseconds."""
    t_ns: tuple[int, ...]
    delay_ns: tuple[int, ...]
    lost: tuple[bool, ...]
    duration_ns: int

    def at(self, t_ns: int) -> tuple[int, bool]:
        """(one-way delay in ns, lost) for a packet sent at session time `t_ns` (>= 0), the trace looped."""
        phase = t_ns % self.duration_ns
        i = bisect.bisect_right(self.t_ns, phase) - 1
        return self.delay_ns[max(i, 0)], self.lost[max(i, 0)]

    @property
    def loss_fraction(self) -> float:
        return sum(self.lost) / len(self.lost)


def parse_trace(lines: list[str], source: str = "trace") -> LinkTrace:
    """Validate and convert CSV text lines (header first); errors name the line."""
    reader = csv.reader(lines)
    header = next(reader, None)
    if header is None or tuple(h.strip() for h in header) != COLUMNS:
        raise ConfigError(f"{source}: the first line must be the header {','.join(COLUMNS)}, not {header!r}")
    t_ns: list[int] = []
    delay_ns: list[int] = []
    lost: list[bool] = []
    for lineno, row in enumerate(reader, start=2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != 3:
            raise ConfigError(f"{source}:{lineno}: expected 3 columns ({','.join(COLUMNS)}), got {len(row)}")
        try:
            t, d = float(row[0]), float(row[1])
        except ValueError as err:
            raise ConfigError(f"{source}:{lineno}: t_s and delay_s must be numbers ({err})") from err
        flag = _LOST.get(row[2].strip().lower())
        if flag is None:
            raise ConfigError(f"{source}:{lineno}: lost must be 0 or 1 (or true/false), not {row[2]!r}")
        if not (math.isfinite(t) and math.isfinite(d)) or d < 0:
            raise ConfigError(f"{source}:{lineno}: t_s must be finite and delay_s finite and >= 0")
        tn = round(t * NS_PER_S)
        if t_ns and tn < t_ns[-1]:
            raise ConfigError(f"{source}:{lineno}: t_s {t} goes back in time (rows must be in send order)")
        t_ns.append(tn)
        delay_ns.append(round(d * NS_PER_S))
        lost.append(flag)
    if len(t_ns) < 2:
        raise ConfigError(f"{source}: a trace needs at least 2 packets, found {len(t_ns)}")
    origin = t_ns[0]
    rel = [t - origin for t in t_ns]
    gaps = [b - a for a, b in pairwise(rel)]
    median_gap = round(statistics.median(gaps))
    duration = rel[-1] + max(median_gap, 1)
    return LinkTrace(tuple(rel), tuple(delay_ns), tuple(lost), duration)


@functools.lru_cache(maxsize=8)
def _load_cached(path: str, mtime_ns: int, size: int) -> LinkTrace:
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigError(f"cannot read link trace {path}: {err}") from err
    return parse_trace(text.splitlines(), path)


def load_trace(path: str | Path) -> LinkTrace:
    """The trace in the CSV file at `path` (cached per file version)."""
    p = Path(path)
    try:
        st = p.stat()
    except OSError as err:
        raise ConfigError(f"link trace not found: {p} ({err.strerror})") from err
    return _load_cached(str(p), st.st_mtime_ns, st.st_size)


def describe(trace: LinkTrace) -> str:
    """One line: packets, duration, loss and the delay percentiles of the delivered packets."""
    ds = sorted(d for d, lost in zip(trace.delay_ns, trace.lost, strict=True) if not lost)
    pct = {q: ds[min(int(len(ds) * q), len(ds) - 1)] / 1e6 for q in (0.5, 0.99)} if ds else {0.5: 0.0, 0.99: 0.0}
    return (f"{len(trace.t_ns)} packets over {trace.duration_ns / NS_PER_S:.1f} s, loss {100 * trace.loss_fraction:.2f} %,"
            f" delay p50 {pct[0.5]:.1f} ms, p99 {pct[0.99]:.1f} ms, max {(ds[-1] if ds else 0) / 1e6:.1f} ms")


if __name__ == "__main__":   # python -m sea_hil.protocol.link_trace FILE.csv [...]: check and describe traces
    import sys
    for arg in sys.argv[1:]:
        print(f"{arg}: {describe(load_trace(arg))}")
