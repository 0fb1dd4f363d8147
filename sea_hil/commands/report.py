"""`sea-hil report`: figures, report.md and summary.json from a session recording."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from sea_hil.errors import RecordingError
from sea_hil.report.writer import run_report


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("report", help="figures and report.md from a session recording (MCAP)")
    p.add_argument("recording", type=Path, metavar="RUN.mcap")
    p.add_argument("--out", type=Path, required=True, metavar="DIR")
    p.set_defaults(func=_main)


def _main(args: argparse.Namespace) -> int:
    if not args.recording.is_file():
        raise RecordingError(f"no such recording: {args.recording}")
    print(json.dumps(run_report(args.recording, args.out), indent=2, sort_keys=True))
    return 0
