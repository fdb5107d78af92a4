"""Accuracy by slip magnitude: bins, boundaries, empty bins, pixels at the model's input, and
the figures `vtsbench eval` writes."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from tests.fixtures.submissions import slip_split, write_submission
from vtsbench.cli import app
from vtsbench.dataset.format.records import SCHEMA_DIR
from vtsbench.evaluation.magnitude import (
    MAGNITUDE_EDGES_MM,
    by_magnitude,
    distances,
    per_state,
    slip_motion,
)
from vtsbench.evaluation.submission import load_truth


def test_bin_boundaries_are_half_open() -> None:
    mm = np.array([0.0, 0.1, 0.0999999, 0.2, 0.4, 0.8, 5.0])
    res = by_magnitude(np.ones(7, bool), mm, mm * 10)
    assert [b["n"] for b in res["bins"]] == [2, 1, 1, 1, 2]
    assert res["bins"][-1]["hi_mm"] is None and res["edges_mm"][-1] is None
    assert res["bins"][0]["px_max"] == pytest.approx(0.999999)


def test_empty_bins_and_unknown_motion() -> None:
    res = by_magnitude([True, False, True], [0.15, 0.15, math.nan], [1.0, 3.0, math.nan])
    b = {(x["lo_mm"]): x for x in res["bins"]}
    assert b[0.1] == {"lo_mm": 0.1, "hi_mm": 0.2, "n": 2, "correct": 1, "accuracy": 0.5,
                      "px_min": 1.0, "px_median": 2.0, "px_max": 3.0}
    assert b[0.0]["n"] == 0 and b[0.0]["accuracy"] is None and b[0.0]["px_median"] is None
    assert res["n_unknown"] == 1 and res["n_outside"] == 0
    empty = by_magnitude([], [], [])
    assert all(x["n"] == 0 and x["accuracy"] is None for x in empty["bins"])


def test_outside_edges_and_bad_edges() -> None:
    res = by_magnitude([True, True], [0.05, 2.0], [1, 1], edges=(0.1, 1.0))
    assert res["bins"][0]["n"] == 0 and res["n_outside"] == 2
    with pytest.raises(ValueError):
        by_magnitude([True], [0.1], [1.0], edges=(1.0, 0.5))
    with pytest.raises(ValueError):
        by_magnitude([True, False], [0.1], [1.0])


def test_pixels_at_the_input_follow_the_scale_per_axis() -> None:
    motion = {"dx_mm": np.array([0.3, 0.0]), "dy_mm": np.array([0.0, 0.4]),
              "mm_per_px_x": np.array([0.03, 0.03]), "mm_per_px_y": np.array([0.02, 0.02])}
    mm, px = distances(motion)
    np.testing.assert_allclose(mm, [0.3, 0.4])
    np.testing.assert_allclose(px, [10.0, 20.0])
    _, px = distances(motion, [0.5, 0.25])
    np.testing.assert_allclose(px, [5.0, 5.0])


def test_per_state() -> None:
    res = per_state([0, 0, 2, 2], [0, 1, 2, 2], ("static", "press", "slip"))
    assert res == {"static": {"n": 2, "accuracy": 0.5}, "press": {"n": 0, "accuracy": None},
                   "slip": {"n": 2, "accuracy": 1.0}}


def test_eval_writes_magnitude_bins(vts_dataset: Path, tmp_path: Path) -> None:
    import jsonschema

    split, part = slip_split(vts_dataset)
    sub = write_submission(vts_dataset, tmp_path / "sub", split, part, wrong=1)
    meta = json.loads(sub.with_suffix(".meta.json").read_text())
    sub.with_suffix(".meta.json").write_text(json.dumps({**meta, "input_scale_xy": [0.5, 0.5]}))
    out = tmp_path / "ev"
    res = CliRunner().invoke(app, ["eval", str(sub), "--dataset", str(vts_dataset), "--split",
                                   split, "--part", part, "--out", str(out)])
    assert res.exit_code == 0, res.output
    doc = json.loads((out / "metrics.json").read_text())
    jsonschema.validate(doc, json.loads((SCHEMA_DIR / "metrics.schema.json").read_text()))
    d = doc["tasks"]["direction"]["runs"][0]
    bm = d["by_magnitude"]
    assert len(bm["bins"]) == len(MAGNITUDE_EDGES_MM) - 1
    assert sum(b["n"] for b in bm["bins"]) + bm["n_unknown"] + bm["n_outside"] == d["n"]
    if bm["n_unknown"] == bm["n_outside"] == 0:  # one direction made wrong on purpose
        assert sum(b["correct"] for b in bm["bins"]) == d["n"] - 1
    truth = load_truth(vts_dataset, split, part)
    slips = [s for s, st in zip(truth.ids, truth.labels["state"], strict=True) if st == 2]
    mm, px_full = distances(slip_motion(vts_dataset, slips))
    for b in bm["bins"]:
        if b["n"]:
            inside = (mm >= b["lo_mm"]) & (mm < (b["hi_mm"] or np.inf))
            assert b["px_max"] == pytest.approx(0.5 * px_full[inside].max())
    ps = doc["tasks"]["state"]["runs"][0]["per_state"]
    assert ps["slip"]["n"] == len(slips) and ps["slip"]["accuracy"] == 1.0
    assert "Direction by slip distance" in (out / "report.md").read_text()
