"""summary.json's `verdict`: did the run test what it meant to? `ok`, `degraded` or `invalid`, with every reason, its
figure and its threshold (docs/verdict.md).

- `invalid`: a drive latched its safe state (a soft-limit fault, a watchdog trip, an e-stop: `drive_faults`); the
  limb stopped following the controller, whatever the tracking figures say.
- `degraded`: a counter above its `[verdict]` threshold (`COUNTER_RULES`): driver tick misses (and the cia402
  profile's SYNC misses) beyond the host's own floor, late samples, late or lost setpoints and states, envelope rejections, saturated inner steps, rejections,
  recording losses, a recording incomplete against the nodes' own counters (`completeness`, issue 32).

Pure: summary (and thresholds) in, verdict out, so `sea-hil report` on the recording reproduces `run`'s. A counter
that is absent from the summary (a kind of run that does not have it) gives no reason. A new counter is judged by
adding one `CounterRule` line (a rejection counter: to `REJECTION_COUNTERS`).
"""
from __future__ import annotations

import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from pydantic import ValidationError

from sea_hil.config.loader import validation_line
from sea_hil.config.verdict import VerdictConfig
from sea_hil.errors import ConfigError
from sea_hil.protocol.payload_fields import RejectReason
from sea_hil.verdict.summary_fields import field, sync_periods

OK, DEGRADED, INVALID = "ok", "degraded", "invalid"
STRICT_EXIT = 3   # `--strict`: the exit status of a run whose verdict is not ok


def _edge_feedback(s: Mapping[str, Any]) -> float | None:
    return field(s, "edge", "feedback_samples")


def _inner_steps(s: Mapping[str, Any]) -> float | None:
    return field(s, "edge", "commands_sent", default=field(s, "inner_steps"))


@dataclass(frozen=True)
class CounterRule:
    """One counter of summary.json (`path`, looked up also under `timing`), degraded above `[verdict].threshold`;
    with `per`, the threshold is a percentage of what `per` returns; `realtime_only`: not judged in lockstep."""
    code: str
    path: tuple[str, ...]
    threshold: str
    what: str
    per: Callable[[Mapping[str, Any]], float | None] | None = None
    realtime_only: bool = False


# rejection counters: each degrades the run above `[verdict] rejections_max` (one line per new counter)
REJECTION_COUNTERS: tuple[tuple[tuple[str, ...], str], ...] = (
    (("edge", "rejected_frames"), "CAN frames the edge rejected (malformed)"),
    (("edge", "rejected_samples"), "feedback samples the edge rejected (sample time not advancing)"),
    *((("rejections", f"payload_rejected_{r.value}"), f"Zenoh payloads the edge rejected ({r.value})")
      for r in RejectReason),
    (("edge", "unexpected_payloads"), "payloads of an unexpected type at the edge"),
    (("edge", "epoch_foreign"), "payloads of a foreign session epoch at the edge"),
    (("edge", "bus_errors"), "CAN bus errors at the edge"),
)

COUNTER_RULES: tuple[CounterRule, ...] = (
    CounterRule("late_samples", ("edge", "late_samples"), "late_samples_max_pct",
                "feedback samples left unanswered (older than safety.setpoint.max_sample_age_s)", _edge_feedback,
                realtime_only=True),
    CounterRule("late_setpoints", ("edge", "late_setpoints"), "late_setpoints_max",
                "setpoints dropped: their state was older than safety.setpoint.max_answer_age_s"),
    CounterRule("lost_setpoints", ("edge", "seq_lost"), "lost_setpoints_max",
                "setpoints lost on the way to the edge (beyond the downlink model's own drops)"),
    CounterRule("lost_states", ("link_losses", "uplink_beyond_model"), "lost_states_max",
                "states lost on the way to the controller (beyond the uplink model's own drops)"),
    CounterRule("stale_setpoints", ("edge", "stale_setpoints"), "stale_setpoints_max",
                "setpoints dropped as stale or duplicated", realtime_only=True),
    CounterRule("envelope_rejections", ("edge", "setpoints_out_of_envelope"), "envelope_rejections_max",
                "setpoints rejected outside the setpoint envelope [safety.setpoint]"),
    CounterRule("saturated_steps", ("edge", "saturated_steps"), "saturated_steps_max_pct",
                "inner-loop steps with the voltage clipped at plant.voltage_limit_v", _inner_steps),
    CounterRule("saturated_steps", ("saturated_steps",), "saturated_steps_max_pct",
                "inner-loop steps with the voltage clipped at plant.voltage_limit_v", _inner_steps),
    CounterRule("recording_losses", ("recording", "lost"), "recording_losses_max",
                "messages the recorder dropped or could not write"),
    *(CounterRule("rejections", path, "rejections_max", what) for path, what in REJECTION_COUNTERS),
)


def _reason(code: str, severity: str, message: str, value: Any, threshold: Any, **extra: Any) -> dict[str, Any]:
    return {"code": code, "severity": severity, "message": message, "value": value, "threshold": threshold, **extra}


def _fault_reasons(summary: Mapping[str, Any]) -> list[dict[str, Any]]:
    out = []
    for f in summary.get("drive_faults") or []:
        if f.get("after_session"):
            continue   # the designed safe state after the last measured sample (sea_hil/report/drive_faults.py)
        flags = "|".join(f["flags"]) or "no flags"
        limit = any(n.endswith("_LIMIT") for n in f["flags"])
        code = "estop" if f["state"] == "ESTOP" else \
            "watchdog_trip" if "WATCHDOG" in f["flags"] and not limit else "drive_fault"
        t = "at an unrecorded time" if f.get("t_s") is None else f"at {f['t_s']:.3f} s"
        held = "" if f.get("in_fault_s") is None else \
            f", {f['in_fault_s']:.2f} s in {f['state']}" + ("" if f.get("cleared") else " (still latched at the end)")
        out.append(_reason(code, INVALID, f"drive {f['node_id']} latched {f['state']} {flags} {t}{held}; "
                                          f"{f['clear_policy']}", f.get("t_s"), None, **{k: f.get(k) for k in (
                               "node_id", "state", "flags", "t_s", "in_fault_s", "cleared")}))
    return out


def _deadline_reason(code: str, what: str, misses: int, total: int, floor: Mapping[str, Any], max_pct: float,
                     factor: float, names: tuple[str, str], unit: str) -> list[dict[str, Any]]:
    """Real-time deadlines (`misses` of `total`) beyond `max_pct` % plus `factor` x the host's empty-loop floor: the
    emulator's, not the host's (docs/verdict.md). `names`: the two `[verdict]` keys, for the message."""
    pct = 100.0 * misses / total
    floor_pct = float(floor.get("miss_pct", 0.0))
    limit = max_pct + factor * floor_pct
    if pct <= limit:
        return []
    where = (f"host's empty-loop floor {floor_pct:.3f} % over {floor.get('duration_s', 0):g} s at start-up"
             if floor else "host floor not measured")
    return [_reason(code, DEGRADED, f"{what} {misses} of {total} {unit} ({pct:.3f} %), above {limit:.3f} % = "
                                    f"verdict.{names[0]} {max_pct:g} % + verdict.{names[1]} {factor:g} x the {where}",
                    round(pct, 4), round(limit, 4), floor_pct=floor_pct)]


def _tick_reason(summary: Mapping[str, Any], cfg: VerdictConfig) -> list[dict[str, Any]]:
    drv = field(summary, "driver")
    if summary.get("lockstep", False) or not isinstance(drv, Mapping) or not drv.get("ticks"):
        return []    # lockstep has no deadlines: simulated time waits for every node
    return _deadline_reason("tick_misses", "driver missed", int(drv.get("tick_misses", 0)), int(drv["ticks"]),
                            drv.get("floor") or {}, cfg.tick_miss_max_pct, cfg.tick_miss_floor_factor,
                            ("tick_miss_max_pct", "tick_miss_floor_factor"), "ticks")


def _sync_reason(summary: Mapping[str, Any], cfg: VerdictConfig) -> list[dict[str, Any]]:
    """The cia402 profile's SYNC misses, judged like the driver's tick misses (the SYNC period is the inner loop's:
    a missed one is a sample the limb did not get), against the same host floor."""
    periods = sync_periods(summary)
    if summary.get("lockstep", False) or periods is None:
        return []    # lockstep: one SYNC per answered sample, no deadline
    drv = field(summary, "driver")
    floor = (drv.get("floor") or {}) if isinstance(drv, Mapping) else {}
    return _deadline_reason("sync_misses", "the edge's SYNC producer missed", periods[0], periods[1], floor,
                            cfg.sync_miss_max_pct, cfg.sync_miss_floor_factor,
                            ("sync_miss_max_pct", "sync_miss_floor_factor"), "SYNC periods")


LIMB_SCOPED = ("edge", "rejections", "link_losses")   # blocks each limb has of its own (its nodes' counters)


def _limb_views(summary: Mapping[str, Any]) -> list[tuple[Mapping[str, Any], str | None]]:
    """(summary as one limb sees it, the limb's name) per limb: with several limbs, each `limbs` entry's own `edge`,
    `rejections` and `link_losses` (absent: its controller's stats are not recorded) in place of the top-level ones
    (the first limb's); one limb: the summary itself, unnamed."""
    limbs = summary.get("limbs") or []
    if len(limbs) > 1 and all(isinstance(e.get("edge"), Mapping) for e in limbs):
        return [({**summary, **{k: e.get(k, {}) for k in LIMB_SCOPED}}, str(e["limb"])) for e in limbs]
    return [(summary, None)]


def _counter_reasons(summary: Mapping[str, Any], cfg: VerdictConfig) -> list[dict[str, Any]]:
    """Every `COUNTER_RULES` counter above its threshold; the edge's counters of every limb (reasons name it)."""
    out, seen = [], set()
    lockstep = bool(summary.get("lockstep", False))
    views = _limb_views(summary)
    for rule in COUNTER_RULES:
        if rule.realtime_only and lockstep:
            continue
        for view, limb in views if rule.path[0] in LIMB_SCOPED else [(summary, None)]:
            value = field(view, *rule.path)
            if not isinstance(value, (int, float)) or isinstance(value, bool) or (rule.code, rule.path[-1], limb) \
                    in seen:
                continue
            seen.add((rule.code, rule.path[-1], limb))
            reason = _counter_reason(rule, view, value, getattr(cfg, rule.threshold))
            if reason is not None:
                if limb is not None:
                    reason = {**reason, "message": f"{limb}: {reason['message']}", "limb": limb}
                out.append(reason)
    return out


def _counter_reason(rule: CounterRule, summary: Mapping[str, Any], value: float, threshold: float
                    ) -> dict[str, Any] | None:
    """The reason `rule` gives for `value` (None: within its threshold)."""
    name = ".".join(rule.path)
    if rule.per is not None:
        base = rule.per(summary)
        if not base:
            return None
        pct = 100.0 * value / base
        if pct <= threshold:
            return None
        return _reason(rule.code, DEGRADED, f"{rule.what}: {value:g} of {base:g} ({pct:.3f} %, {name}), above "
                                            f"verdict.{rule.threshold} = {threshold:g} %", round(pct, 4), threshold,
                       counter=name, count=value)
    if value <= threshold:
        return None
    return _reason(rule.code, DEGRADED, f"{rule.what}: {value:g} ({name}), above verdict.{rule.threshold} = "
                                        f"{threshold:g}", value, threshold, counter=name)


# channels of summary.json `completeness` judged here; `can_frames` is the driver's feedback frames missing from their
# seq gaps (a driver numbers every sample it sends: a gap is a frame lost; the VOLTAGE_CMD gaps, which may be samples
# the edge did not answer, are `recording.can_command_gaps`, not judged: `can_command` checks those frames)
COMPLETENESS_JUDGED = ("state", "downlink", "can_command", "can_frames")


def _completeness_reasons(summary: Mapping[str, Any], cfg: VerdictConfig) -> list[dict[str, Any]]:
    """A recording that lacks messages the nodes' own counters say were sent (issue 32: `incomplete`, more than
    `recording_losses_max` missing), or that cannot be checked because a node's final record is not in the file
    (`unverified`: a recorder started late or cut off; `sea-hil report --node-summary` supplies it)."""
    comp = summary.get("completeness")
    if not isinstance(comp, Mapping):
        return []
    out = []
    for name, c in (comp.get("channels") or {}).items():
        if name.split(".")[0] not in COMPLETENESS_JUDGED or not isinstance(c, Mapping):   # state.<limb>: per limb
            continue
        if c.get("status") == "incomplete" and (c.get("missing") or 0) > cfg.recording_losses_max:
            out.append(_reason("recording_incomplete", DEGRADED, f"recording of {name}: {c['missing']} of "
                                                               f"{c['expected']} messages missing ({c.get('source')})"
                                                               f", above verdict.recording_losses_max = "
                                                               f"{cfg.recording_losses_max}", c["missing"],
                               cfg.recording_losses_max, channel=name))
        elif c.get("status") == "unverified":
            out.append(_reason("recording_unverified", DEGRADED, f"recording of {name}: {c.get('recorded', 0)} "
                                                               f"messages, not checked against the sender's count "
                                                               f"(its final statistics are not in the file)",
                               c.get("recorded", 0), None, channel=name))
    return out


def verdict(summary: Mapping[str, Any], cfg: VerdictConfig | None = None) -> dict[str, Any]:
    """The verdict of a summary (see the module docstring)."""
    cfg = cfg or VerdictConfig()
    reasons = _fault_reasons(summary) + _tick_reason(summary, cfg) + _sync_reason(summary, cfg) \
        + _counter_reasons(summary, cfg) \
        + _completeness_reasons(summary, cfg)
    status = INVALID if any(r["severity"] == INVALID for r in reasons) else DEGRADED if reasons else OK
    return {"status": status, "reasons": reasons}


def verdict_config_of(toml_text: str | bytes | None) -> VerdictConfig:
    """`[verdict]` of a recording's attached config.toml (the defaults when there is none). A table that does not
    validate (a hand-edited or foreign file) is a `ConfigError` naming the key: judging under the defaults instead
    would give a verdict the session's own thresholds did not (docs/verdict.md)."""
    if not toml_text:
        return VerdictConfig()
    try:
        text = toml_text.decode() if isinstance(toml_text, bytes) else toml_text
        table = tomllib.loads(text).get("verdict", {})
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as err:
        raise ConfigError(f"the recording's config.toml cannot be read, so neither can its [verdict] thresholds: "
                          f"{err}") from err
    try:
        return VerdictConfig.model_validate(table)
    except ValidationError as err:
        raise ConfigError(f"the recording's config.toml has a bad [verdict] table: "
                          f"{validation_line(err, 'verdict.')}") from err


def strict_status(summary: Mapping[str, Any]) -> int:
    """`--strict`'s exit status for a summary: 0 when its verdict is ok, else `STRICT_EXIT`."""
    return 0 if (summary.get("verdict") or {}).get("status") == OK else STRICT_EXIT
