"""`sea-hil report`: figures, report.md and summary.json from a session recording; its verdict (docs/verdict.md) on
stderr, at the top of report.md and in summary.json."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from sea_hil.errors import ConfigError, RecordingError
from sea_hil.report.console import files_in, print_end_of_run, verdict_rows
from sea_hil.report.node_summary import KINDS
from sea_hil.report.writer import run_report


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("report", help="figures and report.md from a session recording (MCAP)")
    p.add_argument("recording", type=Path, metavar="RUN.mcap")
    p.add_argument("--out", type=Path, required=True, metavar="DIR")
    p.add_argument("--json", action="store_true", help="print summary.json instead of the end-of-run table")
    p.add_argument("--node-summary", action="append", type=Path, default=[], metavar="NODE.json",
                   help="a node's `--json` result (sea-hil edge|controller ... --json > NODE.json on its host): its "
                        "counters check the recording where the file lacks that node's final statistics (a "
                        "recorder cut off or started late; repeatable)")
    p.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    if not args.recording.is_file():
        raise RecordingError(f"no such recording: {args.recording}")
    summary = run_report(args.recording, args.out, node_counters_of(args.node_summary))
    if args.json:
        print(json.dumps(summary, indent=2, sort_keys=True))
        for what, value in verdict_rows(summary):   # the verdict on stderr too: stdout stays the summary's JSON
            print(f"sea-hil report: {what.strip()}: {value}", file=sys.stderr)
    else:   # the whole session's result, as `run` ends (the verdict first; the recording against the nodes' counters)
        print_end_of_run(summary, files_in(args.out), command="report")
    return 0


def node_counters_of(paths: list[Path]) -> list[tuple[str, dict[str, Any]]]:
    """(node kind, counters) of each `--node-summary` file (its last line: a node's `--json` output). Checked for
    the fields used (the node's kind and numeric counters); the full schema is NODE_SUMMARY_SCHEMA (jsonschema is a
    dev dependency only). Two of one kind are refused (`ConfigError`) unless both say which node they are and the
    nodes differ (`node_id`: the edges or controllers of different limbs), so none silently replaces another."""
    out: list[tuple[str, dict[str, Any]]] = []
    seen: list[tuple[str, Any, Path]] = []
    for path in paths:
        try:
            summary = json.loads(path.read_text(encoding="utf-8").strip().splitlines()[-1])
        except (OSError, IndexError, ValueError) as err:
            raise ConfigError(f"--node-summary {path}: cannot read a node summary: {err}") from err
        counters = summary.get("counters") if isinstance(summary, dict) else None
        if not isinstance(counters, dict) or summary.get("node") not in KINDS or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) for v in counters.values()):
            raise ConfigError(f"--node-summary {path}: not a node summary (the last line of sea-hil NODE ... --json)")
        kind, node_id = summary["node"], counters.get("node_id")
        for other_kind, other_id, other in seen:
            if other_kind == kind and (node_id is None or other_id is None or node_id == other_id):
                which = "" if node_id is None or other_id is None else f" of node {node_id}"
                raise ConfigError(f"--node-summary {path}: a second {kind} summary{which} (the first: {other}); "
                                  f"give each node's once (several limbs: each limb's, told apart by node_id)")
        seen.append((kind, node_id, path))
        out.append((kind, counters))
    return out
