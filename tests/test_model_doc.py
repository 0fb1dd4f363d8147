"""docs/model.md states the model the code implements (issue 29: the docs sent the reader to `../shared/paper.md`,
outside the repository, for the moment arm, M and N): no doc points outside the repository, every function and
config key model.md names exists in the code, and its mass matrix and N terms, written out as formulas, give what
`sea_hil.mechanics` computes. The pytest plugin's dependency has an install extra (`.[test]`)."""
from __future__ import annotations

import dataclasses
import math
import re
import tomllib
from pathlib import Path

from sea_hil import dynamics, mechanics
from sea_hil.config.loader import load_config
from sea_hil.config.model import PlantConfig
from sea_hil.protocol.payloads import StatePayload

REPO = Path(__file__).resolve().parents[1]
MODEL = REPO / "docs" / "model.md"


def test_no_doc_points_outside_the_repository() -> None:
    for path in [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]:
        assert "../shared" not in path.read_text(encoding="utf-8"), path.name


def test_model_doc_names_only_what_the_code_has() -> None:
    text = MODEL.read_text(encoding="utf-8")
    names = set(re.findall(r"`([a-z][a-z0-9_]*)`", text))
    code = set(dir(mechanics)) | set(dir(dynamics)) | set(PlantConfig.model_fields) \
        | set(mechanics.LimbParams._fields) | set(type(load_config().sim).model_fields) \
        | {f.name for f in dataclasses.fields(StatePayload)}          # the wire's names of the same quantities
    missing = {n for n in names if n not in code and not n.startswith(("x", "u"))}
    assert not missing, missing
    assert "docs/model.md" in (REPO / "sea_hil" / "mechanics.py").read_text(encoding="utf-8")


def test_model_doc_formulas_are_the_codes_m_and_n() -> None:
    """M11, M12, M22, N1, N2 as docs/model.md writes them, against `mass_matrix` and `n_terms`."""
    cfg = load_config().plant
    p = mechanics.limb_params(cfg)
    m1, m2, r1, r2, l1, i1, i2, g = cfg.m1_kg, cfg.m2_kg, cfg.r1_m, cfg.r2_m, cfg.l1_m, cfg.i1_kgm2, cfg.i2_kgm2, \
        cfg.g_m_s2
    assert cfg.include_i2_in_coupling
    for q1, q2, w1, w2 in ((0.1, 0.3, 0.2, -0.4), (-0.4, 1.1, -1.0, 0.7)):
        m11 = m1 * r1**2 + i1 + m2 * l1**2 + m2 * r2**2 + i2 + 2 * m2 * l1 * r2 * math.cos(q2)
        m12 = m2 * r2**2 + i2 + m2 * l1 * r2 * math.cos(q2)
        m22 = m2 * r2**2 + i2
        n1 = -(m1 * r1 + m2 * l1) * g * math.sin(q1) + m2 * r2 * g * math.sin(q2 - q1) \
            - m2 * l1 * r2 * math.sin(q2) * (w2**2 - 2 * w1 * w2) - cfg.b1_nms * w1
        n2 = -m2 * r2 * g * math.sin(q2 - q1) - m2 * l1 * r2 * math.sin(q2) * w1**2 - cfg.b2_nms * w2
        for got, want in zip((*mechanics.mass_matrix(q2, p), *mechanics.n_terms(q1, q2, w1, w2, p)),
                             (m11, m12, m22, n1, n2), strict=True):
            assert math.isclose(got, want, rel_tol=1e-12, abs_tol=1e-12)


def test_the_pytest_plugin_has_an_install_extra() -> None:
    extras = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]["optional-dependencies"]
    assert any(dep.startswith("pytest") for dep in extras["test"])
    assert '.[test]' in (REPO / "README.md").read_text(encoding="utf-8")
