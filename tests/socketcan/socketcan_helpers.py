"""Helpers for the SocketCAN tests: interface probe, candump -L parsing, a managed candump subprocess."""
from __future__ import annotations

import queue
import re
import subprocess
import threading
from pathlib import Path
from typing import NamedTuple

PROCESS_TIMEOUT_S = 10.0
CANDUMP_LINE = re.compile(r"^\((?P<t>[0-9.]+)\)\s+(?P<chan>\S+)\s+(?P<id>[0-9A-Fa-f]+)#(?P<data>[0-9A-Fa-f]*)$")


def interface_is_up(name: str) -> bool:
    """True if network interface ``name`` exists here and is administratively up."""
    try:
        return bool(int(Path(f"/sys/class/net/{name}/flags").read_text().strip(), 16) & 0x1)
    except (OSError, ValueError):
        return False


class CandumpFrame(NamedTuple):
    """One frame as printed by ``candump -L``."""

    channel: str
    arbitration_id: int
    is_extended_id: bool
    data: bytes


def parse_candump_line(line: str) -> CandumpFrame:
    """Parse a ``candump -L`` log line such as ``(1700000000.000001) vcan0 123#DEADBEEF``."""
    match = CANDUMP_LINE.match(line.strip())
    if match is None:
        raise ValueError(f"not a classic-CAN candump -L line: {line!r}")
    return CandumpFrame(match["chan"], int(match["id"], 16), len(match["id"]) == 8, bytes.fromhex(match["data"]))


class CanDump:
    """A ``candump -L`` subprocess whose output lines are queued by a reader thread."""

    def __init__(self, channel: str, *args: str, filters: str = "") -> None:
        """Start ``candump -L [args] channel[,filters]`` (filters in candump syntax, e.g. "123:7FF")."""
        interface = f"{channel},{filters}" if filters else channel
        self._proc = subprocess.Popen(["candump", "-L", *args, interface], stdin=subprocess.DEVNULL,
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self._lines: queue.Queue[str | None] = queue.Queue()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self._proc.stdout is not None
        for line in self._proc.stdout:
            self._lines.put(line.rstrip("\n"))
        self._lines.put(None)

    def next_frame(self, timeout_s: float) -> CandumpFrame | None:
        """The next frame candump printed, or None if none arrived within ``timeout_s`` or candump ended."""
        try:
            line = self._lines.get(timeout=timeout_s)
        except queue.Empty:
            return None
        if line is None:
            self._lines.put(None)  # keep signalling end-of-output to later callers
            return None
        return parse_candump_line(line)

    def newest_frames(self, timeout_s: float, every: frozenset[str] = frozenset()) -> list[CandumpFrame]:
        """Every line queued so far (waiting up to ``timeout_s`` for the first), of which only the newest per CAN id
        is parsed, and every one of the ids in ``every`` (hex, as candump prints them), in the order printed. For a
        reader slower than the bus (a slow guest): it never falls behind the dump. Empty if nothing arrived or
        candump ended."""
        newest: dict[str, str] = {}
        kept: list[str] = []
        line: str | None = ""
        try:
            line = self._lines.get(timeout=timeout_s)
            while line is not None:
                can_id = line.rsplit(" ", 1)[-1].split("#", 1)[0]
                if can_id in every:
                    kept.append(line)
                newest[can_id] = line
                line = self._lines.get_nowait()
        except queue.Empty:
            pass
        if line is None:
            self._lines.put(None)  # keep signalling end-of-output to later callers
        lines = kept + [text for can_id, text in newest.items() if can_id not in every]
        return [parse_candump_line(text) for text in lines]

    def wait(self, timeout_s: float = PROCESS_TIMEOUT_S) -> int:
        """Wait for candump to exit (e.g. after ``-n N`` frames) and return its exit status."""
        return self._proc.wait(timeout=timeout_s)

    def stop(self) -> None:
        """End candump (terminate, then kill) and reap it; safe to call twice."""
        if self._proc.poll() is None:
            self._proc.terminate()
            try:
                self._proc.wait(timeout=PROCESS_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()
        self._reader.join(timeout=PROCESS_TIMEOUT_S)
        for stream in (self._proc.stdout, self._proc.stderr):
            if stream is not None:
                stream.close()
