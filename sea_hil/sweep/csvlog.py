"""sweep.csv as a crash-safe log: every finished point is appended and flushed to the OS the moment it arrives, so
a crash or a kill of the sweep loses no finished point; the file is fsynced at most every `SYNC_S` (and on close), so
only a crash of the machine itself could lose the rows of its last second (an fsync per row cost a sweep of
thousands of points seconds of disk waits); `--resume` reads it back and skips points already done with the same
effective config (same point name and config hash). At the end the file is rewritten in point order (atomically)."""
from __future__ import annotations

import csv
import math
import os
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from sea_hil.errors import ConfigError
from sea_hil.sweep.grid import CSV_COLUMNS

SYNC_S = 1.0        # fsync sweep.csv at most this often (rows are flushed to the OS at once)


def read_rows(path: Path) -> list[dict[str, Any]]:
    """The rows of an existing sweep.csv (values as strings); [] if there is none. A file with other columns is an
    error (it was not written by this version of `sea-hil sweep`)."""
    if not path.exists():
        return []
    try:
        with path.open(newline="", encoding="utf-8") as fh:
            reader = csv.DictReader(fh)
            if reader.fieldnames is None:
                return []
            if tuple(reader.fieldnames) != CSV_COLUMNS:
                raise ConfigError(f"{path}: not a sweep.csv of this version (columns differ); move it away to "
                                  "start afresh")
            return [parse_row(row) for row in reader if row.get("point")]
    except (OSError, UnicodeDecodeError, csv.Error) as err:
        raise ConfigError(f"cannot read {path}: {err}") from err


def _value(text: str) -> Any:
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


TEXT_COLUMNS = ("point", "controller", "trigger", "compensation", "edge_model", "link", "status", "error",
                "config_sha256", "verdict", "verdict_reasons")


def parse_row(row: dict[str, str]) -> dict[str, Any]:
    """A row as read back: numbers as numbers (as the sweep wrote them), empty cells as ""."""
    return {k: (v if k in TEXT_COLUMNS or v == "" else _value(v)) for k, v in row.items()}


def finished(rows: Iterable[dict[str, Any]]) -> dict[tuple[str, str], dict[str, Any]]:
    """(point name, config hash) -> row, for the points that completed ok (the ones `--resume` skips)."""
    return {(r["point"], r["config_sha256"]): r for r in rows if r.get("status") == "ok"}


class CsvLog:
    """Append-only writer of sweep.csv rows (header written once, each row flushed, fsynced every `sync_s`)."""

    def __init__(self, path: Path, *, keep_existing: bool, sync_s: float = SYNC_S) -> None:
        self.path, self.sync_s, self._synced = path, sync_s, -math.inf
        path.parent.mkdir(parents=True, exist_ok=True)
        fresh = not keep_existing or not path.exists() or path.stat().st_size == 0
        self._fh = path.open("w" if fresh else "a", newline="", encoding="utf-8")
        self._writer = csv.DictWriter(self._fh, fieldnames=CSV_COLUMNS)
        if fresh:
            self._writer.writeheader()
            self._sync()

    def append(self, row: dict[str, Any]) -> None:
        self._writer.writerow(row)
        self._fh.flush()
        if time.monotonic() - self._synced >= self.sync_s:
            self._sync()

    def _sync(self) -> None:
        self._fh.flush()
        os.fsync(self._fh.fileno())
        self._synced = time.monotonic()

    def close(self) -> None:
        if not self._fh.closed:
            self._sync()
            self._fh.close()

    def __enter__(self) -> CsvLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def write_csv(path: Path, rows: Iterable[dict[str, Any]]) -> None:
    """Rewrite sweep.csv with `rows` (atomic: a temporary file renamed over it)."""
    tmp = path.with_suffix(".csv.tmp")
    with tmp.open("w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=CSV_COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)
