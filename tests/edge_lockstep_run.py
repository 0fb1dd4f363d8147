"""A live lockstep session with the trigger at the edge and prediction (short trajectory, seed 1), for the tests that
compare it with the offline engine (tests/test_session_engine.py, tests/test_edge_fallback.py)."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]


def run_live_edge_lockstep(tmp_path: Path, spec: str) -> tuple[Path, dict[str, Any]]:
    """`sea-hil run --lockstep --trigger edge --compensation predict` with `spec` each way on a 2 s trajectory with
    the edge's model lookahead; -> (the config file it used, its summary.json)."""
    cfg_file = tmp_path / "short.toml"
    cfg_file.write_text("[trajectory]\nperiod_s = 2.0\nlead_in_s = 0.3\n\n[trigger]\nedge_model = true\n",
                        encoding="utf-8")
    proc = subprocess.run([sys.executable, "-m", "sea_hil.cli", "run", "--lockstep", "--quiet", "--controller", "et",
                           "--cycles", "1", "--seed", "1", "--config", str(cfg_file), "--trigger", "edge",
                           "--compensation", "predict", "--uplink", spec, "--downlink", spec,
                           "--out", str(tmp_path / "run")], cwd=ROOT, capture_output=True, text=True,
                          timeout=300, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, proc.stderr
    return cfg_file, json.loads((tmp_path / "run" / "summary.json").read_text())
