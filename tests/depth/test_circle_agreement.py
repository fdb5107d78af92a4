"""`calibrate --circles detect` says how far the detected circles lie from the labels."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.fixtures.calibration import sim_folder
from vtsbench.cli import app
from vtsbench.depth.calibration import label_agreement
from vtsbench.depth.report import circles_vs_labels


@pytest.fixture(scope="module")
def sim(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return sim_folder(tmp_path_factory)


def test_agreement_of_one_circle_clamps_both_radii_below_the_ball() -> None:
    a = label_agreement((10.0, 20.0, 15.0), (13.0, 24.0, 16.5), ball_px=100.0)
    assert a["label_offset_px"] == 5.0 and math.isclose(a["label_radius_error"], 0.1)
    # a label (20 px) and a detection (19 px) beyond 0.97 of a 16 px ball both become 15.52
    a = label_agreement((0.0, 0.0, 20.0), (0.0, 0.0, 19.0), ball_px=16.0)
    assert a["label_radius_error"] == 0.0


def _row(source, label=True, off=None, rad=None, status="used"):
    row = {"id": "p", "source": source, "label": {"x": 0, "y": 0, "r": 10} if label else None,
           "status": status}
    if off is not None:
        row.update(label_offset_px=off, label_radius_error=rad)
    return row


def test_summary_counts_each_labelled_press_and_a_miss_as_outside() -> None:
    rows = [_row("detected", off=1.0, rad=0.02), _row("detected", off=3.0, rad=-0.10),
            _row("detected", off=3.01, rad=0.0), _row("detected", off=0.5, rad=0.12),
            _row("detected", status="dropped"),  # labelled, nothing detected
            _row("detected", label=False)]  # no label: not compared
    s = circles_vs_labels(rows)
    assert s["presses"] == 5 and s["detected"] == 4
    assert s["share_centre"] == 3 / 5  # 3.0 px is within (the bound is inclusive)
    assert s["share_radius"] == 3 / 5 and s["share_both"] == 2 / 5
    assert s["centre_median_px"] == 2.0 and s["centre_max_px"] == 3.01
    assert s["beyond_px"] == ["p"]  # the one at 3.01 px
    # label mode (labels used, nothing compared), and no labels at all: no summary
    assert circles_vs_labels([_row("label")]) is None
    assert circles_vs_labels([_row("detected", label=False, off=None)]) is None
    assert circles_vs_labels([]) is None


def test_cli_detect_prints_and_reports_the_agreement(sim, tmp_path) -> None:
    out = tmp_path / "d.safetensors"
    res = CliRunner().invoke(app, ["calibrate", str(sim), "--out", str(out), "--holdout", "2",
                                   "--circles", "detect"])
    assert res.exit_code == 0, res.output
    line = next(x for x in res.stdout.splitlines() if x.startswith("detected circles against"))
    assert "against the 10 labels" in line and "100% within 3 px" in line, line
    js = json.loads((tmp_path / "d.safetensors.report" / "report.json").read_text())
    agree = js["circles_vs_labels"]
    # Measured on these simulated presses (exact circles): centres 0.02-0.21 px off.
    assert agree["presses"] == 10 and agree["share_both"] == 1.0
    assert agree["centre_max_px"] < 1.5
    assert all("label_offset_px" in r for r in js["circles"])
    res = CliRunner().invoke(app, ["calibrate", str(sim), "--out", str(tmp_path / "l.st"),
                                   "--holdout", "2"])
    assert res.exit_code == 0 and "detected circles against" not in res.stdout
    js = json.loads((tmp_path / "l.st.report" / "report.json").read_text())
    assert js["circles_vs_labels"] is None


def test_detect_run_scores_its_held_out_presses_against_the_labels(sim, tmp_path) -> None:
    """Without simulated truth the reference is the sphere at a circle: a run on detected
    circles says what its held-out presses score against their labels too (the figure a run
    on the labels gives), and the calibration file keeps it (schema-checked on save)."""
    from dataclasses import replace

    from tests.fixtures.calibration import copy_folder
    from vtsbench.depth.calibration import load_calibration

    folder = tmp_path / "no-truth"
    copy_folder(sim, folder, edit=lambda e, s: ([replace(x, truth=None) for x in e], s))
    out = tmp_path / "d.safetensors"
    res = CliRunner().invoke(app, ["calibrate", str(folder), "--out", str(out), "--holdout",
                                   "2", "--seed", "1", "--circles", "detect"])
    assert res.exit_code == 0, res.output
    assert "the same 2 held-out press(es) scored against their labelled circles" in res.stdout
    fit = load_calibration(out).fit
    vs = fit["holdout_vs_labels"]
    assert vs["presses"] == 2 and vs["ids"] == [h["id"] for h in fit["holdout"]]
    # exact labels and circles detected within 0.21 px: the two references agree closely
    # (measured 0.0059 mm against the labels, 0.0062 mm against the detected circles)
    detected = fit["holdout_mean"]["plane_aligned_rmse_mm"]
    assert abs(vs["plane_aligned_rmse_mm"] - detected) < 0.25 * detected
    # with simulated truth the reference is the truth whatever the circle: nothing to add
    res = CliRunner().invoke(app, ["calibrate", str(sim), "--out", str(tmp_path / "t.st"),
                                   "--holdout", "2", "--circles", "detect"])
    assert res.exit_code == 0 and "scored against their labelled" not in res.stdout
    assert load_calibration(tmp_path / "t.st").fit["holdout_vs_labels"]["presses"] == 0
