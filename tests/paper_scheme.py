"""The paper's event-triggered scheme as config overrides, for tests about the paper's scheme (issue 16 made the
trigger at the edge with model lookahead and delay compensation the default): the trigger at the controller (every
state crosses the uplink) and no delay compensation. CLI: `--trigger controller --compensation none`."""
from __future__ import annotations

from typing import Any

PAPER_SCHEME: dict[str, Any] = {"trigger": {"placement": "controller", "edge_model": False},
                                "controller": {"compensation": "none"}}
PAPER_FLAGS = ["--trigger", "controller", "--compensation", "none"]


def paper(overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """`overrides` on top of the paper's scheme (a deep merge: their own trigger / controller keys are kept)."""
    out = {k: dict(v) for k, v in PAPER_SCHEME.items()}
    for key, val in (overrides or {}).items():
        out[key] = {**out[key], **val} if key in out and isinstance(val, dict) else val
    return out
