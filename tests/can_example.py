"""Running examples/can_controller (which imports nothing of sea-hil) against sea-hil's emulated driver started here:
`run_on_virtual` puts both on one python-can `virtual` channel in this process, the driver in lockstep (it advances
one sample per answered feedback), and returns the example's summary. Used by tests/test_examples.py and
tests/socketcan/test_can_controller_vcan.py."""
from __future__ import annotations

import runpy
import threading
import tomllib
import uuid
from pathlib import Path
from typing import Any

import can

from sea_hil.config.loader import config_to_toml
from sea_hil.config.root import SeaHilConfig
from sea_hil.plant_emulator.node import PlantNode
from sea_hil.runtime.lockstep import clock_for

CAN_EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "can_controller"


def load_example() -> dict[str, Any]:
    """The example's module namespace (CanController, load_dbc, DEFAULT_DBC, main)."""
    return runpy.run_path(str(CAN_EXAMPLE / "controller.py"), run_name="can_example")


def run_on_virtual(cfg: SeaHilConfig, cycles: int = 1, timeout_s: float = 120.0) -> tuple[dict[str, Any], PlantNode]:
    """(the example's summary, the driver node) after `cycles` cycles on a fresh virtual channel."""
    example = load_example()
    channel = f"byoc-{uuid.uuid4().hex}"
    plant_bus, ctrl_bus = can.Bus(interface="virtual", channel=channel), can.Bus(interface="virtual", channel=channel)
    plant = PlantNode(cfg, plant_bus, (1,), clock=clock_for(True))
    thread = threading.Thread(target=plant.run, daemon=True)
    ctrl = example["CanController"](tomllib.loads(config_to_toml(cfg)), example["load_dbc"](example["DEFAULT_DBC"]),
                                    ctrl_bus, node_id=1, cycles=cycles)
    thread.start()
    try:
        ctrl.run(timeout_s=timeout_s)
    finally:
        plant.stop()
        thread.join(10)
        plant_bus.shutdown()
        ctrl_bus.shutdown()
    return ctrl.summary(), plant
