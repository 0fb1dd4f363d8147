"""Malformed TOML configs and CLI arguments: exit status 2, one clear stderr line, no traceback -- both through
`sea_hil.cli.main` in-process and through the installed `sea-hil` console script."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from sea_hil.cli import main

BAD_TOML = {
    "syntax": "[plant\nx = 1\n",
    "type": '[can]\nwatchdog_timeout_s = "fast"\n',
    "unknown_section": "[nosuch]\na = 1\n",
    "unknown_key": "[can]\nbitrate = 5\n",
    "table_replaced": "plant = 5\n",
    "range": "[can]\nnode_ids = [0]\n",
    "nan": "[plant]\nm1_kg = nan\n",
    "bad_interface": '[can]\ninterface = "foo:bar"\n',
    "bad_limb": '[zenoh]\nlimb = "a/b"\n',
}


def one_error_line(err: str, command: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err
    assert len(lines) == 1, err
    assert lines[0].startswith(f"sea-hil {command}: error: "), err
    return lines[0]


@pytest.mark.parametrize("name", sorted(BAD_TOML))
def test_bad_toml_config_is_one_clear_line(name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cfg = tmp_path / "bad.toml"
    cfg.write_text(BAD_TOML[name], encoding="utf-8")
    assert main(["simulate", "--config", str(cfg), "--out", str(tmp_path / "out")]) == 2
    line = one_error_line(capsys.readouterr().err, "simulate")
    assert "config" in line


@pytest.mark.parametrize("path_kind", ["missing", "directory", "binary"])
def test_unreadable_config_file(path_kind: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = {"missing": tmp_path / "none.toml", "directory": tmp_path}.get(path_kind, tmp_path / "bin.toml")
    if path_kind == "binary":
        path.write_bytes(b"\xff\xfe\x00")
    assert main(["simulate", "--config", str(path), "--out", str(tmp_path / "out")]) == 2
    one_error_line(capsys.readouterr().err, "simulate")


BAD_ARGS = [
    ["run", "--cycles", "0"],
    ["run", "--certs", "{tmp}/no-certs", "--out", "{tmp}/o"],
    ["run", "--secure", "--listen", "tcp/127.0.0.1:{port}", "--out", "{tmp}/o"],
    ["simulate", "--cycles", "0", "--out", "{tmp}/o"],
    ["simulate", "--trajectory", "{tmp}/none.csv", "--out", "{tmp}/o"],
    ["plant", "--rate", "0"],
    ["plant", "--watchdog", "-1"],
    ["plant", "--can", "foo:bar"],
    ["plant", "--can", "udp_multicast:10.0.0.1"],
    ["plant", "--node", "99"],
    ["edge", "--node", "0"],
    ["edge", "--uplink", "delay=abc"],
    ["edge", "--downlink", "loss=150%"],
    ["edge", "--connect", "nonsense"],
    ["controller", "--limb", "a/b"],
    ["record", "--out", "{tmp}/no/such/dir/x.mcap", "--listen", "tcp/127.0.0.1:{port}"],
    ["report", "{tmp}/none.mcap", "--out", "{tmp}/r"],
]


@pytest.mark.parametrize("argv", BAD_ARGS, ids=lambda a: "-".join(a[:3]))
def test_bad_cli_values_are_one_clear_line(argv: list[str], tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    from sea_hil.protocol.zsession import free_tcp_port
    args = [a.format(tmp=tmp_path, port=free_tcp_port()) for a in argv]
    assert main(args) == 2
    one_error_line(capsys.readouterr().err, argv[0])


@pytest.mark.parametrize("argv", [["run", "--cycles", "abc"], ["plant", "--rate", "fast"], ["simulate"],
                                  ["edge", "--inner", "cloud"], ["nosuch"]])
def test_argparse_errors_exit_2_without_traceback(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith("sea-hil") and ": error: " in lines[0] and lines[0].endswith("--help)")


def test_console_script_prints_one_line_and_exits_2(tmp_path: Path) -> None:
    cfg = tmp_path / "bad.toml"
    cfg.write_text(BAD_TOML["type"], encoding="utf-8")
    res = subprocess.run([sys.executable, "-m", "sea_hil.cli", "plant", "--config", str(cfg)], capture_output=True,
                         text=True, timeout=60, stdin=subprocess.DEVNULL)
    assert res.returncode == 2 and res.stdout == ""
    assert "watchdog_timeout_s" in one_error_line(res.stderr, "plant")
