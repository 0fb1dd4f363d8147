"""Keys of older config files: each rate has one source now, and keys read by nothing are gone.

A renamed key is moved to its one source with a `FutureWarning`; if the same file (or override layer) also sets the
new key to a different value, that is a `ConfigError` (the two used to configure offline runs and sessions apart, so
which one was meant is unknown). A removed key is dropped with a `FutureWarning`.
"""
from __future__ import annotations

import warnings
from typing import Any

from sea_hil.errors import ConfigError

# old (section, key) -> new (section, key), same unit
RENAMED: dict[tuple[str, str], tuple[str, str]] = {
    ("controller", "inner_rate_hz"): ("can", "feedback_rate_hz"),     # inner loop = one step per drive feedback
    ("zenoh", "state_period_s"): ("controller", "sample_period_s"),   # the edge publishes once per outer sample
}
REMOVED: dict[tuple[str, str], str] = {
    ("can", "send_backoff_s"): "read by nothing (the nodes pause 0.2 ms between CAN send retries)",
    ("record", "stats_period_s"): "read by nothing (nodes publish /stats at shutdown, docs/recording.md)",
    # real-time levers measured as no gain once the session runs at SCHED_FIFO (docs/timing.md, "Measured")
    ("timing", "spin_us"): "measured as no gain and removed (docs/timing.md); the driver sleeps to each deadline",
    ("timing", "gc_in_slack"): "measured as no gain (twice the tick misses) and removed (docs/timing.md)",
    ("timing", "gc_slack_us"): "belonged to the removed gc_in_slack (docs/timing.md)",
    ("timing", "switch_interval_us"): "measured as no gain and removed (docs/timing.md); Python's default applies",
    ("timing", "driver_cpu"): "measured as no gain and removed (docs/timing.md); no thread or process is pinned",
}


def migrate_layer(data: dict[str, Any], source: str) -> dict[str, Any]:
    """One config layer (a user file or overrides, nested dict) with old keys moved or dropped; `source` names the
    layer in messages. The input is not modified."""
    out = {k: dict(v) if isinstance(v, dict) else v for k, v in data.items()}
    for (sec, key), (new_sec, new_key) in RENAMED.items():
        section = out.get(sec)
        if not isinstance(section, dict) or key not in section:
            continue
        value = section.pop(key)
        target = out.setdefault(new_sec, {})
        if not isinstance(target, dict):
            continue            # not a table: validation reports it
        if new_key in target and target[new_key] != value:
            raise ConfigError(f"{source}: {sec}.{key} = {value!r} contradicts {new_sec}.{new_key} = "
                              f"{target[new_key]!r}; {sec}.{key} was replaced by {new_sec}.{new_key} (one source "
                              f"for offline runs and sessions): remove {sec}.{key}")
        target.setdefault(new_key, value)
        warnings.warn(f"{source}: {sec}.{key} is deprecated, use {new_sec}.{new_key} (now {value!r}, offline and "
                      "in sessions)", FutureWarning, stacklevel=3)
    for (sec, key), why in REMOVED.items():
        section = out.get(sec)
        if isinstance(section, dict) and key in section:
            section.pop(key)
            warnings.warn(f"{source}: {sec}.{key} was removed and is ignored: {why}", FutureWarning, stacklevel=3)
    return out
