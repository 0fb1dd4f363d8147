"""The `sea-hil` console script: one entry point, one subcommand per node or job.

Each subcommand lives in its own module `sea_hil/commands/<name>.py` exposing `register(subparsers)`; only the
module of the command being run is imported (a node process loads what its node needs, not the sweep's Dask or the
report's matplotlib), every module for `sea-hil --help`. Errors derived from SeaHilError print one line and exit 2
(no traceback).
"""
from __future__ import annotations

import argparse
import importlib
import logging
import sys
from typing import NoReturn

from sea_hil.errors import SeaHilError, Terminated
from sea_hil.runtime.processes import exit_with_parent

COMMANDS = ("simulate", "plant", "edge", "controller", "record", "router", "run", "report", "export", "sweep",
            "robustness", "certs", "check")


class OneLineParser(argparse.ArgumentParser):
    """argparse with one-line errors: `sea-hil run: error: ... (see sea-hil run --help)`, exit 2, no usage dump."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of every command, or of `command` alone (when it is one of COMMANDS)."""
    parser = OneLineParser(prog="sea-hil", description=(
        "Networked HIL emulator: event-triggered SMC of a 2-DOF SEA lower limb over CAN and Zenoh."))
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more logging (-v info, -vv debug)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in (command,) if command in COMMANDS else COMMANDS:
        try:
            module = importlib.import_module(f"sea_hil.commands.{name}")
        except ModuleNotFoundError as err:
            if err.name != f"sea_hil.commands.{name}":
                raise
            continue
        module.register(sub)
    return parser


def command_of(argv: list[str]) -> str | None:
    """The subcommand named in `argv` (its first word that is not an option: the top level takes only -v)."""
    return next((a for a in argv if not a.startswith("-")), None)


def main(argv: list[str] | None = None) -> int:
    exit_with_parent()   # a child of a sea-hil session (`spawn_child`) ends when its parent dies
    argv = sys.argv[1:] if argv is None else argv
    parser = build_parser(command_of(argv))
    args = parser.parse_args(argv)
    level = logging.WARNING - 10 * min(args.verbose, 2)
    logging.basicConfig(level=level, format="%(asctime)s %(name)s %(levelname)s: %(message)s")
    try:
        return int(args.func(args) or 0)
    except Terminated as err:   # SIGTERM/SIGHUP: the close path has run; the shell's exit status of that signal
        print(f"sea-hil {args.command}: {err}", file=sys.stderr)
        return 128 + err.signum
    except SeaHilError as err:
        print(f"sea-hil {args.command}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
