"""`sea-hil report`: figures, report.md and summary.json from a session recording; its verdict (docs/verdict.md) on
stderr, at the top of report.md and in summary.json."""
from __future__ import annotations

import argparse
import json
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("report", help="figures and report.md from a session recording (MCAP)")
    p.add_argument("recording", type=Path, metavar="RUN.mcap")
    p.add_argument("--out", type=Path, required=True, metavar="DIR")
    p.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    from sea_hil.errors import RecordingError
    from sea_hil.report.writer import run_report
    if not args.recording.is_file():
        raise RecordingError(f"no such recording: {args.recording}")
    summary = run_report(args.recording, args.out)
    print(json.dumps(summary, indent=2, sort_keys=True))
    import sys

    from sea_hil.report.console import verdict_rows
    for what, value in verdict_rows(summary):   # the verdict on stderr too: stdout stays the summary's JSON
        print(f"sea-hil report: {what.strip()}: {value}", file=sys.stderr)
    return 0
