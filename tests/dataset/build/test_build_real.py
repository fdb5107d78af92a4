"""A real recording set end to end: GelSight Mini press videos without a calibration or labels
(octopi) -> vtsbench manifest -> build --no-depth -> verify -> load; skips without the data."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

import vtsbench
from tests.fixtures.data import REAL
from vtsbench.cli import app

OCTOPI = REAL / "octopi_videos"
#: Eight clips of eight objects (all at least 120 frames long).
CLIPS = ("apple_0", "carpet_0", "denim_3", "egg_1", "lemon_1", "orange_2", "pen_2", "sponge_0")

pytestmark = pytest.mark.skipif(not all((OCTOPI / f"{c}.mov").is_file() for c in CLIPS),
                                reason="real recordings (shared/data/real/octopi_videos) absent")


def _cli(*args: str) -> str:
    res = CliRunner().invoke(app, list(args), terminal_width=200)
    assert res.exit_code == 0, res.output
    return " ".join(res.output.split())


def test_octopi_subset_rgb_only(tmp_path: Path) -> None:
    videos = tmp_path / "videos"
    videos.mkdir()
    for c in CLIPS:  # the data folder is read-only: a folder of links to some of its clips
        (videos / f"{c}.mov").symlink_to(OCTOPI / f"{c}.mov")
    rec, out = tmp_path / "rec", tmp_path / "ds"
    _cli("manifest", str(videos), "--pattern", "{object}_{take:d}.mov", "--sensor",
         "gelsight-mini", "--window", "8", "--stride", "48", "--out", str(rec))
    res = CliRunner().invoke(app, ["build", str(rec), str(out), "--quiet"])
    assert res.exit_code == 2 and "--no-depth" in res.output  # no calibration
    text = _cli("build", str(rec), str(out), "--no-depth", "--workers", "2", "--quiet")
    assert "0 entries skipped" in text
    assert "0 problem(s)" in _cli("verify", str(out))
    assert "rgb only" in _cli("info", str(out))

    ds = vtsbench.load(out)
    n = len(json.loads((rec / "recordings.json").read_text())["entries"])
    assert len(ds.slip) == n and len(ds.static) == 0 and ds.arrays == ("rgb",)
    assert sorted(set(ds.slip.index["object"].to_pylist())) == sorted(
        c.rsplit("_", 1)[0] for c in CLIPS)
    sample = ds.slip[len(ds.slip) // 2]
    assert sample["rgb"].shape == (8, 240, 320, 3) and sample["rgb"].dtype.name == "uint8"
    assert sample["state"] is None and sample["mm_per_px"] is None
    assert sample["rgb"].std() > 1  # real frames, not a fill value
    # no labels: the slip splits that need states or sessions are skipped, the object ones made
    assert {"unseen_objects", "object_folds"} <= set(ds.splits)
    report = json.loads((out / "meta" / "build_report.json").read_text())
    assert "seen" in report["splits_skipped"]
