"""The sweep's method and link axes (issue 16), pure: which trigger placement, delay compensation, edge model and
outer sample period a point runs (`Scheme`), the named methods of `--methods`, the `--trigger` / `--compensation`
/ `--period-ms` axes, and explicit link conditions (`--links`: link specs as `--uplink` takes them)."""
from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from sea_hil.errors import ConfigError
from sea_hil.protocol.link import parse_link_spec

TRIGGERS = ("controller", "edge")
COMPENSATIONS = ("none", "predict")


@dataclass(frozen=True)
class Scheme:
    """How a point's loop runs beyond the trigger thresholds; None = the base config's value."""
    placement: str | None = None        # trigger.placement (ET only)
    compensation: str | None = None     # controller.compensation
    edge_model: bool | None = None      # trigger.edge_model (ET with the trigger at the edge)
    period_ms: float | None = None      # controller.sample_period_s in ms (the TT rates)

    def overrides(self) -> dict[str, Any]:
        """Nested config overrides of this scheme."""
        ov: dict[str, dict[str, Any]] = {}
        if self.placement is not None:
            ov.setdefault("trigger", {})["placement"] = self.placement
        if self.edge_model is not None:
            ov.setdefault("trigger", {})["edge_model"] = self.edge_model
        if self.compensation is not None:
            ov.setdefault("controller", {})["compensation"] = self.compensation
        if self.period_ms is not None:
            ov.setdefault("controller", {})["sample_period_s"] = self.period_ms / 1000.0
        return ov

    def tag(self) -> str:
        """Point-name suffix ("" for the base config's scheme, so plain sweeps keep their names)."""
        parts = [self.placement or "", self.compensation or "",
                 {True: "model", False: "nomodel", None: ""}[self.edge_model],
                 "" if self.period_ms is None else f"T{self.period_ms:g}"]
        return "".join(f"_{p}" for p in parts if p)


# --methods: (controller, scheme) presets; TT ones run at every --period-ms
METHODS: dict[str, tuple[str, Scheme]] = {
    "tt": ("tt", Scheme(compensation="none")),
    "tt-predict": ("tt", Scheme(compensation="predict")),
    "et-paper": ("et", Scheme(placement="controller", compensation="none", edge_model=False)),
    "et-edge": ("et", Scheme(placement="edge", compensation="predict", edge_model=True)),
}
# --links presets: the four links of issue 16's acceptance table (each way)
LINK_PRESETS: dict[str, tuple[str, ...]] = {
    "issue16": ("ideal", "delay=5ms,jitter=1ms,dist=normal,loss=1%", "delay=10ms,jitter=2ms,dist=normal,loss=2%",
                "delay=20ms,jitter=5ms,ge=0.01/0.3/0.8")}


def parse_choices(option: str, text: str, choices: Sequence[str]) -> tuple[str, ...]:
    """'controller,edge' -> ('controller', 'edge'); a ConfigError naming the option otherwise."""
    parts = [p.strip() for p in text.split(",")]
    if not text.strip() or any(not p for p in parts):
        raise ConfigError(f"{option} {text!r}: expected a comma-separated list of {', '.join(choices)}")
    bad = [p for p in parts if p not in choices]
    if bad:
        raise ConfigError(f"{option}: {bad[0]!r} is not one of {', '.join(choices)}")
    if len(set(parts)) != len(parts):
        raise ConfigError(f"{option} {text!r}: repeated value")
    return tuple(parts)


def schemes_from_axes(triggers: Sequence[str] | None, compensations: Sequence[str] | None,
                      periods_ms: Sequence[float] | None) -> tuple[list[Scheme], list[Scheme]]:
    """(TT schemes, ET schemes): TT at every period x compensation; ET at every trigger placement x compensation
    (the base config's sample period: --period-ms gives the periodic baselines' rates). None = the config's."""
    comps: Sequence[str | None] = compensations or (None,)
    tt = [Scheme(compensation=c, period_ms=p) for p, c in itertools.product(periods_ms or (None,), comps)]
    et = [Scheme(placement=t, compensation=c) for t, c in itertools.product(triggers or (None,), comps)]
    return tt, et


def schemes_from_methods(names: Sequence[str], periods_ms: Sequence[float] | None
                         ) -> tuple[list[Scheme], list[Scheme]]:
    """(TT schemes, ET schemes) of the named `--methods`; TT methods at every --period-ms."""
    tt: list[Scheme] = []
    et: list[Scheme] = []
    for name in names:
        controller, scheme = METHODS[name]
        if controller == "tt":
            tt += [Scheme(compensation=scheme.compensation, period_ms=p) for p in (periods_ms or (None,))]
        else:
            et.append(scheme)
    return tt, et


def parse_links(text: str) -> tuple[str, ...]:
    """`--links`: ';'-separated link specs (the `--uplink` syntax), `ideal`, or a preset name (issue16) -> the
    specs ('' = ideal), each checked by the link parser."""
    items = [p.strip() for p in text.split(";")]
    if not text.strip() or any(not p for p in items):
        raise ConfigError(f"--links {text!r}: expected ';'-separated link specs, 'ideal' or "
                          f"{', '.join(LINK_PRESETS)}")
    specs: list[str] = []
    for item in items:
        for spec in LINK_PRESETS.get(item, (item,)):
            spec = "" if spec == "ideal" else spec
            try:
                parse_link_spec(spec)
            except ConfigError as err:
                raise ConfigError(f"--links: {err}") from err
            specs.append(spec)
    if len(set(specs)) != len(specs):
        raise ConfigError(f"--links {text!r}: repeated link")
    return tuple(specs)
