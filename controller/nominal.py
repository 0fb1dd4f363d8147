"""The controller's nominal model: `[plant]` overlaid with `[controller.model]` (the plant emulator integrates
`[plant]` alone, so the two differ exactly where `[controller.model]` or `--mismatch` says)."""
from __future__ import annotations

from sea_hil.config.root import SeaHilConfig
from sea_hil.mechanics import LimbParams, limb_params


def nominal_params(cfg: SeaHilConfig) -> LimbParams:
    """LimbParams of the nominal model, used by the outer SMC, the inner loop and the disturbance observer."""
    return limb_params(cfg.controller.model.resolve(cfg.plant))
