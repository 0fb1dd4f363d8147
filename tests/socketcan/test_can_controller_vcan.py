"""examples/can_controller on a real SocketCAN vcan0: the example process (python-can socketcan + the DBC, nothing of
sea-hil) drives `sea-hil plant --can socketcan:vcan0 --lockstep` and tracks exactly as it does on python-can
`virtual` (tests/test_examples.py compares that run with the built-in controller). Short (0.2 s lead-in + a 0.5 s
cycle): UML is slow.

    scripts/with-vcan -- python -m pytest -q tests/socketcan/test_can_controller_vcan.py
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from can_example import CAN_EXAMPLE, run_on_virtual

from sea_hil.config.loader import config_to_toml, load_config
from sea_hil.runtime.processes import end_process

REPO = Path(__file__).resolve().parents[2]
CFG = {"trajectory": {"period_s": 0.5, "lead_in_s": 0.2}}   # 0.7 s of driver time: the guest is slow


def test_can_example_on_vcan0_tracks_as_on_virtual(tmp_path: Path, vcan_channel: str) -> None:
    cfg = load_config(overrides=CFG)
    cfg_path = tmp_path / "config.toml"
    cfg_path.write_text(config_to_toml(cfg), encoding="utf-8")
    plant = subprocess.Popen([sys.executable, "-m", "sea_hil.cli", "plant", "--can", f"socketcan:{vcan_channel}",
                              "--lockstep", "--config", str(cfg_path)], cwd=REPO, stdin=subprocess.DEVNULL,
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    ctrl = subprocess.Popen([sys.executable, str(CAN_EXAMPLE / "controller.py"), "--interface", "socketcan",
                             "--channel", vcan_channel, "--config", str(cfg_path), "--timeout", "150"], cwd=REPO,
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        out, err = ctrl.communicate(timeout=200)
    finally:
        end_process(ctrl)
        end_process(plant)
    assert ctrl.returncode == 0, err
    on_vcan = json.loads(out)
    on_virtual, _ = run_on_virtual(cfg)
    assert on_vcan["done"] and on_vcan["rejected"] == 0 and on_vcan["commands"] >= 600
    assert on_vcan["max_abs_error_rad"] == on_virtual["max_abs_error_rad"]
    assert on_vcan["events"] == on_virtual["events"]
