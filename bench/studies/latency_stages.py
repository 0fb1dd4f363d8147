"""Where the closed-loop latency goes: per-stage times of real-time `sea-hil run --controller et --cycles 1` sessions.

Run: python -m bench.studies.latency_stages [--runs 3] [--sea-hil PATH ...] [--probe] [--json OUT]
Every process of each session (the run process with plant + edge + recorder taps, the controller child) gets the
stamps of `bench/studies/latency_probe.py` through a `sitecustomize` on PYTHONPATH (the product is not changed):
each hot `put` (state, setpoint) before and after, each state/setpoint subscriber callback's entry, each payload
decode. Matched by payload bytes on the host's one monotonic clock, per answered state k:
  edge put       the edge's `put` of state k (the figure starts just before it: `sent_at`)
  uplink         put returned -> the controller's subscriber callback (zenoh's receiving thread)
  wake           callback -> the controller's decode of k (its handling thread woke and took the GIL); a C
                 callback is not stamped: then only `uplink+wake`, put returned -> decode
  compute        decode -> `put` of the setpoint answering k (checks, the core's `on_state`, encoding)
  setpoint put   that `put`
  downlink       put returned -> the edge's setpoint callback (with `--probe`: -> zenoh's receiving thread at the
                 edge, then `edge hop`: -> the product's callback)
  total          edge put start -> edge setpoint callback (~ the edge's `latency` figure, which is stamped there)
`--sea-hil` takes several executables (e.g. /work/wt-base/.venv/bin/sea-hil and this checkout's): runs interleave
them (A, B, A, B ...), each reported apart. Per stage the median and p99 over the pooled answered states.
"""
from __future__ import annotations

import argparse
import json
import os
import pickle
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from bench.benchlib import REPO, pct
from sea_hil.errors import MalformedPayload
from sea_hil.protocol.payloads import SetpointPayload, StatePayload, decode

PROBE = REPO / "bench" / "studies" / "latency_probe.py"
SITE = f'''import os
if os.environ.get("SEA_HIL_STAGES_DIR"):
    import importlib.util
    _spec = importlib.util.spec_from_file_location("_sea_hil_latency_probe", {str(PROBE)!r})
    _mod = importlib.util.module_from_spec(_spec)
    _spec.loader.exec_module(_mod)
    _mod.install(os.environ["SEA_HIL_STAGES_DIR"])
'''
STAGES = ("edge put", "uplink", "wake", "uplink+wake", "compute", "compute cpu", "setpoint put", "downlink", "edge hop", "total", "record")


def run_session(sea_hil: str, out: Path, probe: bool) -> dict[str, Any]:
    """One session with the probe in every process; the stamps of each process and the summary."""
    stamps_dir = out / "stamps"
    stamps_dir.mkdir(parents=True)
    site = out / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(SITE, encoding="utf-8")
    env = {**os.environ, "PYTHONPATH": str(site), "SEA_HIL_STAGES_DIR": str(stamps_dir),
           "SEA_HIL_STAGES_PROBE": "1" if probe else "0"}
    cmd = [sea_hil, "run", "--controller", "et", "--cycles", "1", "--out", str(out / "run"), "--quiet",
           "--no-figures"]
    done = subprocess.run(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=300, check=False)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{done.stdout.decode(errors='replace')[-2000:]}")
    procs = [pickle.loads(p.read_bytes()) for p in stamps_dir.glob("*.pkl")]
    summary = json.loads((out / "run" / "summary.json").read_text(encoding="utf-8"))
    return {"procs": procs, "summary": summary}


def _payload(data: bytes) -> Any:
    try:
        return decode(data)
    except MalformedPayload:
        return None


def stages(procs: list[dict[str, Any]]) -> dict[str, list[float]]:
    """Per stage, the times (us) of every answered state."""
    ctrl = next(p for p in procs if "controller" in p["argv"])
    host = next(p for p in procs if "run" in p["argv"] and p is not ctrl)
    st_put: dict[int, tuple[int, int]] = {}
    sp_cb: dict[int, int] = {}
    sp_probe: dict[int, int] = {}
    open_put: dict[bytes, int] = {}
    for t, kind, key, data, _tid, _cpu in host["stamps"]:
        p = _payload(data) if key or kind == "decode" else None
        if kind == "put0" and isinstance(p, StatePayload):
            open_put[data] = t
        elif kind == "put1" and isinstance(p, StatePayload):
            st_put[p.seq] = (open_put.pop(data, t), t)
        elif kind in ("cb", "cb_direct") and isinstance(p, SetpointPayload):
            sp_cb.setdefault(p.state_seq, t)
        elif kind == "probe" and isinstance(p, SetpointPayload):
            sp_probe.setdefault(p.state_seq, t)
    st_cb: dict[int, int] = {}
    st_dec: dict[int, int] = {}
    sp_put: dict[int, tuple[int, int]] = {}
    after: dict[int, int] = {}
    comp_cpu: dict[int, int] = {}
    open_put.clear()
    last_sp: int | None = None
    dec_cpu: dict[int, int] = {}
    for t, kind, key, data, _tid, cpu in ctrl["stamps"]:
        p = _payload(data)
        if kind in ("cb", "cb_direct") and isinstance(p, StatePayload):
            st_cb.setdefault(p.seq, t)
        elif kind == "decode" and isinstance(p, StatePayload):
            st_dec.setdefault(p.seq, t)
            dec_cpu.setdefault(p.seq, cpu)
            last_sp = None
        elif kind == "put1" and key.endswith("/event") and last_sp is not None:
            after.setdefault(last_sp, t)   # the tracking record's put after the setpoint's
            last_sp = None
        elif kind == "put0" and isinstance(p, SetpointPayload):
            open_put[data] = t
            if p.state_seq in dec_cpu:
                comp_cpu[p.state_seq] = cpu - dec_cpu[p.state_seq]
        elif kind == "put1" and isinstance(p, SetpointPayload):
            sp_put[p.state_seq] = (open_put.pop(data, t), t)
            last_sp = p.state_seq
    out: dict[str, list[float]] = {s: [] for s in STAGES}
    for k, (sp0, sp1) in sp_put.items():
        if k not in st_put or k not in sp_cb or k not in st_dec:
            continue
        e0, e1 = st_put[k]
        rows = {"edge put": e1 - e0, "uplink+wake": st_dec[k] - e1, "compute": sp0 - st_dec[k],
                "setpoint put": sp1 - sp0, "total": sp_cb[k] - e0}
        if k in st_cb:
            rows["uplink"], rows["wake"] = st_cb[k] - e1, st_dec[k] - st_cb[k]
        if k in after:
            rows["record"] = after[k] - sp1
        if k in comp_cpu:
            rows["compute cpu"] = comp_cpu[k]
        if k in sp_probe:
            rows["downlink"], rows["edge hop"] = sp_probe[k] - sp1, sp_cb[k] - sp_probe[k]
        else:
            rows["downlink"] = sp_cb[k] - sp1
        for name, ns in rows.items():
            out[name].append(ns / 1e3)
    return out


def describe(label: str, pooled: dict[str, list[float]], figures: list[dict[str, float]]) -> dict[str, Any]:
    row: dict[str, Any] = {"checkout": label, "states": len(pooled["total"])}
    for name in STAGES:
        v = pooled[name]
        if v:
            row[f"{name} p50"] = round(pct(v, 50), 1)
            row[f"{name} p99"] = round(pct(v, 99), 1)
    row["figure p50 per run"] = [round(f["p50"]) for f in figures]
    row["figure p99 per run"] = [round(f["p99"]) for f in figures]
    row["figure p50 median"] = statistics.median(f["p50"] for f in figures)
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--sea-hil", nargs="+", default=[str(Path(sys.executable).with_name("sea-hil"))])
    ap.add_argument("--probe", action="store_true", help="stamp arrivals in zenoh's receiving thread too")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    pooled: dict[str, dict[str, list[float]]] = {exe: {s: [] for s in STAGES} for exe in args.sea_hil}
    figures: dict[str, list[dict[str, float]]] = {exe: [] for exe in args.sea_hil}
    with tempfile.TemporaryDirectory(prefix="latency-stages-") as tmp:
        for i in range(args.runs):
            for j, exe in enumerate(args.sea_hil):
                load = os.getloadavg()[0]
                got = run_session(exe, Path(tmp) / f"r{i}-{j}", args.probe)
                per = stages(got["procs"])
                lat = got["summary"]["timing"]["latency_us"]
                figures[exe].append(lat)
                for name, v in per.items():
                    pooled[exe][name] += v
                print(f"run {i + 1} {exe}: load {load:.2f}  figure p50 {lat['p50']:.0f} p99 {lat['p99']:.0f} us  "
                      + "  ".join(f"{n} {pct(v, 50):.0f}" for n, v in per.items() if v), flush=True)
    rows = [describe(exe, pooled[exe], figures[exe]) for exe in args.sea_hil]
    for row in rows:
        print(json.dumps(row))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
