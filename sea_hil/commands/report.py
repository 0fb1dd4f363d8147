"""`sea-hil report`: figures, report.md and summary.json from a session recording."""
from __future__ import annotations

import argparse
import json
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("report", help="figures and report.md from a session recording (MCAP)")
    p.add_argument("recording", type=Path, metavar="RUN.mcap")
    p.add_argument("--out", type=Path, required=True, metavar="DIR")
    p.add_argument("--json", action="store_true", help="print summary.json instead of the end-of-run table")
    p.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    from sea_hil.errors import RecordingError
    from sea_hil.report.console import files_in, print_end_of_run
    from sea_hil.report.writer import run_report
    if not args.recording.is_file():
        raise RecordingError(f"no such recording: {args.recording}")
    summary = run_report(args.recording, args.out)
    if args.json:
        print(json.dumps(summary, indent=2, sort_keys=True))
    else:   # the whole session's result, as `run` ends (the recording against the nodes' counters included)
        print_end_of_run(summary, files_in(args.out), command="report")
    return 0
