"""What a sweep task carries and how its row is logged: an offline point's spec carries its validated config, equal
to the config its TOML (the point's hash, the lockstep input) parses to; sweep.csv rows reach the OS at once (a
reader sees every row appended so far) and are fsynced at most once per `sync_s` and on close."""
from __future__ import annotations

import csv
import tomllib

from sea_hil.config.loader import config_from_dict
from sea_hil.sweep import csvlog
from sea_hil.sweep.grid import CSV_COLUMNS, expand_grid
from sea_hil.sweep.runner import SweepOptions, build_configs, point_spec


def test_offline_spec_config_is_its_toml(tmp_path):
    points = expand_grid((0.3,), (0.1,), (5.0,), (2.0,), (0.02,))
    for extra in ({}, {"disturbance": "knee=sine:0.05Nm@2Hz,hip=constant:0.5Nm", "mismatch": "mass=+20%"}):
        for mode in ("offline", "lockstep"):
            opts = SweepOptions(out=tmp_path, seed=3, mode=mode, **extra)
            cfgs = build_configs(points, opts)
            for p in points:
                spec = point_spec(opts, p, cfgs[p.index])
                if mode == "lockstep":
                    assert spec.config is None
                else:
                    assert spec.config == config_from_dict(tomllib.loads(spec.config_toml))


def test_rows_are_flushed_at_once_and_fsynced_per_second(tmp_path, monkeypatch):
    syncs, now = [], [100.0]
    monkeypatch.setattr(csvlog.os, "fsync", lambda fd: syncs.append(now[0]))
    monkeypatch.setattr(csvlog.time, "monotonic", lambda: now[0])
    path = tmp_path / "sweep.csv"
    row = dict.fromkeys(CSV_COLUMNS, "")
    with csvlog.CsvLog(path, keep_existing=False, sync_s=1.0) as log:
        assert syncs == [100.0]                   # the header
        for i in range(5):
            now[0] += 0.25
            log.append({**row, "point": f"p{i}"})
            with path.open(newline="", encoding="utf-8") as fh:
                assert [r["point"] for r in csv.DictReader(fh)] == [f"p{j}" for j in range(i + 1)]
        assert syncs == [100.0, 101.0]            # once the second since the last fsync has passed
    assert len(syncs) == 3                        # and on close
