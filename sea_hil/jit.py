"""Re-export of `protocol.jit` (it lives in `protocol` because the plant's integrator uses it too, and
plant_emulator never imports sea_hil)."""
from __future__ import annotations

import importlib.util  # noqa: F401  (part of the interface: tests stub importlib.util.find_spec through it)

from protocol.jit import PROJECT_PACKAGES, compiled, loaded, project_callees, source_fingerprint

__all__ = ["PROJECT_PACKAGES", "compiled", "loaded", "project_callees", "source_fingerprint"]
