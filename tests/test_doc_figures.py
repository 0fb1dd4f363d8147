"""docs/external-controller.md's reference figures are a lockstep run's (issue 29: they said 283 setpoints and
0.001895 / 0.003933 rad while the run gives 309 and 0.001988 / 0.003617): one 10 s lockstep session on the default
config, its summary rendered into the marked block, which must equal the doc's."""
from __future__ import annotations

from pathlib import Path

import pytest

from sea_hil.report.doc_figures import block_of, reference_summary, render

pytestmark = pytest.mark.slow
DOC = Path(__file__).resolve().parents[1] / "docs" / "external-controller.md"


def test_the_external_controller_docs_reference_figures_are_a_runs(tmp_path: Path) -> None:
    summary = reference_summary(tmp_path / "run")
    assert block_of(DOC.read_text(encoding="utf-8")) == render(summary)
