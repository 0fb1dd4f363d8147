"""`sea-hil sweep`'s method axes (issue 16): --trigger / --compensation / --period-ms / --methods / --links, the
scheme columns of sweep.csv and the method comparison (methods.png, sweep.md) — a 4-point grid on the offline
engine, run point by point without a cluster (the Dask path is tests/test_sweep_dask.py's)."""
from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from sea_hil.cli import main
from sea_hil.commands.sweep import method_axes
from sea_hil.errors import ConfigError
from sea_hil.sweep.grid import CSV_COLUMNS, expand_grid
from sea_hil.sweep.methods import METHODS, Scheme, parse_choices, parse_links, schemes_from_axes
from sea_hil.sweep.methods_output import curves_by_link, domination_markdown, methods_figure
from sea_hil.sweep.runner import SweepOptions, point_config, point_spec
from sea_hil.sweep.task import run_point


def _args(**kw: object) -> argparse.Namespace:
    base = dict(config=None, period_ms=None, methods=None, trigger=None, compensation=None, links=None)
    return argparse.Namespace(**{**base, **kw})


def test_axes_multiply_tt_over_periods_and_et_over_placements():
    tt, et = schemes_from_axes(("controller", "edge"), ("none", "predict"), (10.0, 30.0))
    assert [(s.period_ms, s.compensation) for s in tt] == [(10, "none"), (10, "predict"), (30, "none"),
                                                            (30, "predict")]
    assert {(s.placement, s.compensation, s.period_ms) for s in et} == \
        {(t, c, None) for t in ("controller", "edge") for c in ("none", "predict")}
    assert schemes_from_axes(None, None, None) == ([Scheme()], [Scheme()])   # the plain sweep's grid, unchanged
    points = expand_grid((0.5,), (0.2,), (0.0,), (0.0,), (0.0,), tt_schemes=tt, et_schemes=et)
    assert len(points) == 8 and len({p.name for p in points}) == 8
    assert points[0].name == "p000_tt_none_T10_d0_j0_l0"
    assert expand_grid((0.5,), (0.2,), (0.0,), (0.0,), (0.0,))[1].name == "p001_et_eta0.5_r0.2_d0_j0_l0"


def test_methods_links_and_their_errors():
    tt, et, links = method_axes(_args(methods="tt-predict,et-paper,et-edge", period_ms="10,20,30", links="issue16"))
    assert [s.period_ms for s in tt] == [10, 20, 30] and {s.compensation for s in tt} == {"predict"}
    assert et == [METHODS["et-paper"][1], METHODS["et-edge"][1]]
    assert [lk.label() for lk in links][1:] == ["delay=5ms,jitter=1ms,dist=normal,loss=1%",
                                                "delay=10ms,jitter=2ms,dist=normal,loss=2%",
                                                "delay=20ms,jitter=5ms,ge=0.01/0.3/0.8"]
    assert (links[0].delay_ms, links[3].delay_ms, links[3].jitter_ms, links[2].loss) == (0.0, 20.0, 5.0, 0.02)
    assert parse_links("ideal;delay=5ms") == ("", "delay=5ms")
    for bad, msg in (("", "expected"), ("delay=5", "--links"), ("ideal;ideal", "repeated")):
        with pytest.raises(ConfigError, match=msg):
            parse_links(bad)
    with pytest.raises(ConfigError, match="--trigger: 'sensor' is not one of controller, edge"):
        parse_choices("--trigger", "sensor", ("controller", "edge"))
    with pytest.raises(ConfigError, match="do not combine"):
        method_axes(_args(methods="et-edge", trigger="edge"))
    with pytest.raises(ConfigError, match="whole multiple"):
        method_axes(_args(period_ms="10,12.5"))


@pytest.mark.parametrize("extra,msg", [(["--links", "ideal", "--loss", "0.1"], "--links replaces"),
                                       (["--methods", "tt,magic"], "--methods: 'magic'"),
                                       (["--compensation", "smith"], "--compensation: 'smith'")])
def test_bad_method_arguments_exit_2_with_one_line(tmp_path, capsys, extra, msg):
    assert main(["sweep", "--out", str(tmp_path / "o"), *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert msg in err and len(err.splitlines()) == 1 and not (tmp_path / "o").exists()


def test_tiny_method_sweep_on_the_offline_engine(tmp_path: Path):
    opts = SweepOptions(out=tmp_path, seed=1)   # the default 10 s gait: each point ~0.2 s on the engine
    tt, et, links = method_axes(_args(methods="tt-predict,et-edge", period_ms="10,20",
                                      links="delay=5ms,jitter=1ms,dist=normal,loss=1%"))
    points = expand_grid((0.5,), (0.2,), (), (), (), tt_schemes=tt + [Scheme(compensation="none")], et_schemes=et,
                         links=links)
    assert len(points) == 4
    cfgs = [point_config(opts, p) for p in points]
    assert [c.controller.sample_period_s for c in cfgs] == [0.01, 0.02, 0.01, 0.01]
    assert (cfgs[3].trigger.placement, cfgs[3].trigger.edge_model, cfgs[3].controller.compensation) == \
        ("edge", True, "predict")
    assert (cfgs[0].link.uplink.jitter_dist, cfgs[0].link.downlink.delay_s) == ("normal", 0.005)
    edge_base = tmp_path / "edge.toml"
    edge_base.write_text('[trigger]\nplacement = "edge"\n', encoding="utf-8")
    assert point_config(SweepOptions(out=tmp_path, config=edge_base), points[0]).trigger.placement == "controller"
    rows = [run_point(point_spec(opts, p, c)) for p, c in zip(points, cfgs, strict=True)]
    assert all(r["status"] == "ok" for r in rows) and all(tuple(r) == CSV_COLUMNS for r in rows)
    assert [(r["trigger"], r["compensation"], r["edge_model"], r["period_ms"]) for r in rows] == \
        [("controller", "predict", False, 10.0), ("controller", "predict", False, 20.0),
         ("controller", "none", False, 10.0), ("edge", "predict", True, 10.0)]
    for r in rows:
        assert r["total_msgs"] == r["uplink_msgs"] + r["downlink_msgs"] and r["total_bytes"] > 0
    assert rows[1]["uplink_msgs"] < 0.6 * rows[0]["uplink_msgs"]      # 20 ms: about half the samples of 10 ms
    assert rows[3]["uplink_msgs"] < rows[0]["uplink_msgs"]            # the edge trigger thins the uplink
    curves = curves_by_link(rows)
    assert list(curves) == [(5.0, 1.0, 0.01, "delay=5ms,jitter=1ms,dist=normal,loss=1%")]
    assert sorted(curves[next(iter(curves))]) == ["ET, trigger at edge + model, compensation predict",
                                                  "TT, compensation none", "TT, compensation predict"]
    methods_figure(tmp_path / "methods.png", rows)    # write_outputs adds it beside pareto.png (test_sweep.py)
    assert (tmp_path / "methods.png").stat().st_size > 10_000
    md = "\n".join(domination_markdown(rows))
    assert "## Methods: total link messages against periodic TT" in md
    assert "ET, trigger at edge + model, compensation predict η=0.5 r=0.2" in md
