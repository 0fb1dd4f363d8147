"""`sea-hil report RUN.mcap --out DIR`: figures and report.md from any session recording."""
from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import numpy as np

from sea_hil.recorder.reader import SessionData, read_session
from sea_hil.report.completeness import NodeCounters, completeness_lines
from sea_hil.report.figures import histogram_cdf_figure, inter_event_figure, series_figure, tracking_figure
from sea_hil.report.limbs import limb_view, recorded_limbs
from sea_hil.report.session_summary import recorded_lockstep, session_summary, tracking_arrays
from sea_hil.report.summary import write_summary
from sea_hil.stats.can_bits import nominal_bits


def _bins(msgs: list, value: Any, t0_ns: int, width_s: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    if not msgs:
        return np.zeros(0), np.zeros(0)
    t = np.array([(m.log_time_ns - t0_ns) * 1e-9 for m in msgs])
    v = np.array([value(m.payload) for m in msgs], dtype=float)
    edges = np.arange(0.0, max(t.max(), 0.0) + width_s, width_s)
    if len(edges) < 2:
        edges = np.array([0.0, width_s])
    sums, _ = np.histogram(t, bins=edges, weights=v)
    return edges[:-1], sums / width_s


def state_to_setpoint_latency_us(data: SessionData) -> np.ndarray:
    """Per event: controller's setpoint send time minus the edge's send time of the state it answers (both
    CLOCK_MONOTONIC of one host: valid for real-time same-host sessions; in lockstep a state's stamp is its release
    on the simulated clock)."""
    sent = {m.payload["seq"]: m.payload["sent_t_ns"] for m in data.messages.get("/zenoh/state", [])}
    out = [(m.payload["sent_t_ns"] - sent[m.payload["state_seq"]]) * 1e-3
           for topic in ("/zenoh/setpoint", "/zenoh/voltage") for m in data.messages.get(topic, [])
           if m.payload.get("state_seq") in sent]
    return np.array([x for x in out if x >= 0])


FIGURES = ("tracking", "inter_event", "latency")


def _limb_figures(data: SessionData, out: Path) -> list[Path]:
    """Tracking, inter-event and latency figures: of the session with one limb; with several, the first limb's
    under the 1-limb names and every limb's as `<figure>_<limb>.png`."""
    limbs = recorded_limbs(data)
    views = [("", "session", data)] if len(limbs) == 1 else \
        [(f"_{name}", name, limb_view(data, name, node_id)) for name, node_id, _ in limbs]
    files: list[Path] = []
    for suffix, title, view in views:
        tr = tracking_arrays(view)
        names = [out / f"{stem}{suffix}.png" for stem in FIGURES]
        tracking_figure(names[0], tr["t_s"], tr["theta_rad"], tr["desired_rad"], title)
        inter_event_figure(names[1], tr["event_t_s"], title)
        histogram_cdf_figure(names[2], state_to_setpoint_latency_us(view), "state sent -> setpoint sent [us]",
                             f"{title}: closed-loop latency")
        files += names
    if len(limbs) > 1:   # the 1-limb names: the first limb's figures
        for stem, src in zip(FIGURES, files, strict=False):   # the first limb's figures
            shutil.copyfile(src, out / f"{stem}.png")
            files.append(out / f"{stem}.png")
    return files


def _bus_of_node(data: SessionData) -> dict[int, str]:
    return {node_id: bus for _, node_id, bus in recorded_limbs(data)}


def write_report_figures(data: SessionData, out: Path) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    files = _limb_figures(data, out)
    files += [out / "bandwidth.png", out / "bus_load.png"]
    all_msgs = [m for v in data.messages.values() for m in v]
    t0 = min((m.log_time_ns for m in all_msgs), default=0)
    series: dict[str, np.ndarray] = {}
    t_axis = np.zeros(0)
    for name, topic in (("downlink setpoint+voltage B/s", "/zenoh/setpoint"), ("uplink state B/s", "/zenoh/state")):
        msgs = data.messages.get(topic, []) + (data.messages.get("/zenoh/voltage", []) if "setpoint" in topic else [])
        t_axis_i, rate = _bins(msgs, lambda p: p["payload_bytes"], t0)
        if len(t_axis_i) > len(t_axis):
            t_axis = t_axis_i
        series[name] = rate
    series_figure(files[-2], t_axis, series, "payload bytes/s", "Zenoh bandwidth")
    meta = data.metadata.get("sea-hil.config", {})
    bitrate, data_rate = int(meta.get("can.bitrate_bps", 1_000_000)), int(meta.get("can.data_bitrate_bps", 5_000_000))
    raw, bus_of = data.messages.get("/can/raw", []), _bus_of_node(data)
    loads: dict[str, np.ndarray] = {}
    tb = np.zeros(0)
    for bus in dict.fromkeys(bus_of.values()):   # every bus (frames of unknown node ids: the first bus)
        first = bus == next(iter(bus_of.values()))
        msgs = [m for m in raw
                if (bus_of[n] if (n := m.payload.get("node_id")) in bus_of else bus if first else None) == bus]
        t_i, bits = _bins(msgs, lambda p: nominal_bits(int(p["dlc"]), fd=bool(p.get("is_fd")), bitrate_bps=bitrate,
                                                       data_bitrate_bps=data_rate), t0)
        tb = t_i if len(t_i) > len(tb) else tb
        loads["bus load %" if len(bus_of) == 1 else f"{bus} load %"] = 100.0 * bits / bitrate
    series_figure(files[-1], tb, loads, "load [%]", "CAN bus load (worst-case stuffing)")
    return files


def _lead_in_rows(summary: dict[str, Any]) -> list[str]:
    lead = summary.get("lead_in") or {}
    if not lead.get("duration_s"):
        return []
    err = lead["tracking"]["max_abs_error_rad"]
    return [f"| lead-in (before the cycles, not counted above): duration [s] / downlink / uplink messages | "
            f"{lead['duration_s']:.2f} / {lead['downlink_msgs']} / {lead['uplink_msgs']} |",
            f"| lead-in max abs tracking error hip / knee [rad] | {err[0]:.5f} / {err[1]:.5f} |"]


def _limb_rows(summary: dict[str, Any]) -> list[str]:
    limbs = summary.get("limbs") or []
    if len(limbs) < 2:
        return []
    rows = ["", "| limb | node id | bus | downlink / uplink msgs | max abs error hip / knee [rad] | latency p50 / p99 [us] |",
            "|---|---|---|---|---|---|"]
    for e in limbs:
        tx, err, lat = e["transmissions"], e["tracking"]["max_abs_error_rad"], e["timing"]["latency_us"]
        rows.append(f"| {e['limb']} | {e['node_id']} | {e['bus']} | {tx['downlink_msgs']} / {tx['uplink_msgs']} | "
                    f"{err[0]:.5f} / {err[1]:.5f} | {lat['p50']:.0f} / {lat['p99']:.0f} |")
    return rows


NOT_RECORDED = "not recorded"


def _if_recorded(comp: dict[str, Any], channel: str, msgs: int, size: int) -> str:
    """`msgs / size`, or "not recorded" when the channel has none in the file and its node's counter is unknown
    (a recorder that was never routed those keys): a zero that is not a measurement (issue 32)."""
    c = (comp.get("channels") or {}).get(channel, {})
    if c.get("status") == "unverified" and not c.get("recorded"):
        return NOT_RECORDED
    if c.get("status") == "incomplete":
        return f"{msgs} / {size} (incomplete: {c['missing']} of {c['expected']} messages not recorded)"
    return f"{msgs} / {size}"


def _or_not_recorded(present: bool, text: str) -> str:
    return text if present else NOT_RECORDED


def _latency(lat: dict[str, Any]) -> str:
    """p50 / p99 / max, or "not recorded": the edge's final statistics (which carry the histogram) are not in the
    file, or it measured no answer (-1 in summary.json, whose schema keeps numbers)."""
    if any(lat.get(k, -1) < 0 for k in ("p50", "p99", "max")):
        return NOT_RECORDED
    return f"{lat['p50']:.0f} / {lat['p99']:.0f} / {lat['max']:.0f}"


def _completeness_rows(comp: dict[str, Any]) -> list[str]:
    """The recording against the nodes' own counters (`sea_hil.report.completeness`)."""
    if not comp:
        return []
    lines = completeness_lines(comp)
    return [f"| recording complete | {'yes' if comp.get('complete') else 'no: ' + '; '.join(lines)} |"]
def _verdict_lines(summary: dict[str, Any]) -> list[str]:
    """The verdict first (docs/verdict.md): its status and every reason."""
    v = summary.get("verdict") or {}
    out = [f"verdict: **{v.get('status', '?')}**", ""]
    out += [f"- {r['severity']}: {r['code']}: {r['message']}" for r in v.get("reasons", [])]
    return out + ([""] if v.get("reasons") else [])


def report_markdown(summary: dict[str, Any], data: SessionData) -> str:
    tx = summary["transmissions"]
    lat = summary["timing"]["latency_us"]
    comp = summary.get("completeness") or {}
    # the controller's records of the measured cycle's tracking (none: no figure; a recorder cut off in the lead-in
    # holds only records at t < 0, and the cycle's figures would be zeros that measure nothing)
    tracked = any(m.payload.get("t_s", -1.0) >= 0 for m in data.messages.get("/tracking", []))
    lines = ["# sea-hil session report", "", *_verdict_lines(summary),
             f"controller: **{summary['controller']}**, duration {summary['duration_s']:.2f} s, "
             f"file complete: {data.complete}, messages: {data.message_count}", "",
             "| figure | value |", "|---|---|",
             f"| downlink messages / bytes | {_if_recorded(comp, 'downlink', tx['downlink_msgs'], tx['downlink_bytes'])} |",
             f"| uplink messages / bytes | {_if_recorded(comp, 'state', tx['uplink_msgs'], tx['uplink_bytes'])} |",
             f"| total link messages / bytes (up + down) | {tx['total_msgs']} / {tx['total_bytes']} |",
             "| max abs tracking error hip / knee [rad] | " + _or_not_recorded(
                 tracked, f"{summary['tracking']['max_abs_error_rad'][0]:.5f} / "
                          f"{summary['tracking']['max_abs_error_rad'][1]:.5f}") + " |",
             "| rms tracking error hip / knee [rad] | " + _or_not_recorded(
                 tracked, f"{summary['tracking']['rms_error_rad'][0]:.5f} / "
                          f"{summary['tracking']['rms_error_rad'][1]:.5f}") + " |",
             "| inter-event min / median / max [s] | " + _or_not_recorded(
                 tracked, f"{summary['inter_event_s']['min']:.3f} / {summary['inter_event_s']['median']:.3f} / "
                          f"{summary['inter_event_s']['max']:.3f}") + " |",
             "| max abs voltage [V] | " + _or_not_recorded(
                 bool(data.messages.get("/can/command")),
                 f"{summary['max_abs_voltage_v'][0]:.2f} / {summary['max_abs_voltage_v'][1]:.2f}") + " |",
             f"| closed-loop latency p50 / p99 / max [us] | {_latency(lat)} |",
             *_lead_in_rows(summary),
             *_limb_rows(summary),
             *_completeness_rows(comp),
             "", "Figures: tracking.png (paper Fig. 2/3), inter_event.png (Fig. 4), latency.png, bandwidth.png, "
             "bus_load.png", ""]
    return "\n".join(lines)


def run_report(path: Path, out: Path, node_counters: NodeCounters | None = None) -> dict[str, Any]:
    """Figures, summary.json and report.md of a recording; `node_counters` ((node kind, its counters) from the
    nodes' `--json` summaries) complete the completeness check where the file lacks a node's final record."""
    data = read_session(path)
    session = data.metadata.get("sea-hil.session", {})
    summary = session_summary(data, session.get("controller", "et"), node_counters)
    summary["lockstep"] = recorded_lockstep(data)   # as `run` says it (the table's mode line, the verdict's rules)
    write_report_figures(data, out)
    write_summary(out / "summary.json", summary)
    (out / "report.md").write_text(report_markdown(summary, data), encoding="utf-8")
    return summary

