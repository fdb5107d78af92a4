"""`vtsbench eval` and `vtsbench leaderboard` end to end on the small built dataset."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.fixtures.submissions import slip_split, write_submission
from vtsbench.cli import app
from vtsbench.dataset.format.info import load_info
from vtsbench.dataset.format.records import SCHEMA_DIR
from vtsbench.evaluation import metrics as M
from vtsbench.evaluation.leaderboard import entry_schema_errors

runner = CliRunner()


def test_eval_end_to_end(vts_dataset: Path, tmp_path: Path) -> None:
    import jsonschema

    split, part = slip_split(vts_dataset)
    sub = write_submission(vts_dataset, tmp_path / "sub", split, part, wrong=1, names=True)
    out = tmp_path / "ev"
    res = runner.invoke(app, ["eval", str(sub), "--dataset", str(vts_dataset), "--split", split,
                              "--part", part, "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "state" in res.output and "direction" in res.output and "100.00" in res.output
    doc = json.loads((out / "metrics.json").read_text())
    jsonschema.validate(doc, json.loads((SCHEMA_DIR / "metrics.schema.json").read_text()))
    assert doc["metric_version"] == M.METRIC_VERSION
    assert doc["tasks"]["state"]["runs"][0]["accuracy"] == 1.0
    d = doc["tasks"]["direction"]["runs"][0]
    assert d["error_bins"][1] == 1 and d["within_one_bin"] == 1.0
    assert d["adjacent_error_share"] == 1.0
    assert d["end_to_end_accuracy"] == d["accuracy"] < 1.0
    for task in ("state", "direction"):
        assert (out / f"confusion_{task}.png").stat().st_size > 1000
    report = (out / "report.md").read_text()
    assert "## Direction" in report and "→ E" in report


def test_eval_malformed_exits_2(vts_dataset: Path, tmp_path: Path) -> None:
    split, part = slip_split(vts_dataset)
    sub = write_submission(vts_dataset, tmp_path, split, part)
    sub.write_text(sub.read_text() + "nope,state,0\n")
    res = runner.invoke(app, ["eval", str(sub), "--dataset", str(vts_dataset), "--split", split,
                              "--part", part])
    assert res.exit_code == 2
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {sub}")
    assert f"ids not in split {split}/{part}: 1 (first: nope)" in lines[0]
    res = runner.invoke(app, ["eval", str(sub), "--dataset", str(vts_dataset), "--split", "x"])
    assert res.exit_code == 2 and "no split 'x'" in res.output


def add_entries(ds: Path, tmp_path: Path, root: Path, split: str, part: str,
                methods: tuple[str, str]) -> Path:
    """`leaderboard add` a right submission under methods[0] and one with a wrong answer under
    methods[1]; the last submission's path."""
    for wrong, method in enumerate(methods):
        sub = write_submission(ds, tmp_path / method, split, part, wrong, method)
        res = runner.invoke(app, ["leaderboard", "add", str(sub), "--dataset", str(ds),
                                  "--split", split, "--part", part, "--root", str(root)])
        assert res.exit_code == 0, res.output
    return sub


def test_leaderboard_add_render_rescore(vts_dataset: Path, tmp_path: Path,
                                        monkeypatch: pytest.MonkeyPatch) -> None:
    split, part = slip_split(vts_dataset)
    root = tmp_path / "lb"
    sub = add_entries(vts_dataset, tmp_path, root, split, part, ("good", "worse"))
    res = runner.invoke(app, ["leaderboard", "add", str(sub), "--dataset", str(vts_dataset),
                              "--split", split, "--part", part, "--root", str(root)])
    assert res.exit_code == 2 and "already on the leaderboard" in res.output
    name = load_info(vts_dataset).name
    entry_files = sorted((root / name / split).glob("*.json"))
    assert len(entry_files) == 2
    for p in entry_files:
        assert entry_schema_errors(json.loads(p.read_text())) == []
    md = (root / name / split / "leaderboard.md").read_text()
    assert md.index("| good |") < md.index("| worse |")
    if split in ("seen", "unseen_objects"):
        assert "paper (reference)" in md
    assert "| 1.0 |" in md

    # a metric correction: a new version and a changed definition of within-one-bin
    original = M.direction_metrics

    def corrected(t, p):
        return {**original(t, p), "within_one_bin": 0.125}

    monkeypatch.setattr(M, "METRIC_VERSION", "1.1")
    monkeypatch.setattr(M, "direction_metrics", corrected)
    res = runner.invoke(app, ["leaderboard", "rescore", "--dataset", str(vts_dataset),
                              "--root", str(root)])
    assert res.exit_code == 0, res.output
    assert "re-scored 2 entries" in res.output
    md2 = (root / name / split / "leaderboard.md").read_text()
    assert "| 1.1 |" in md2 and "| 1.0 |" not in md2 and "| 12.50 |" in md2 and md2 != md
    e = json.loads(entry_files[0].read_text())
    assert e["rescored_from"] == ["1.0"] and e["metric_version"] == "1.1"
    res = runner.invoke(app, ["leaderboard", "render", "--root", str(root)])
    assert res.exit_code == 0 and "12.50" in res.output


def test_leaderboard_ranks_the_newest_dataset_version(vts_dataset: Path, tmp_path: Path) -> None:
    """Entries scored on an earlier dataset version are listed apart, not ranked with the
    current ones; the newest version present is the current one (2.0.0 after 1.0.0, a release
    after its pre-release, build metadata ignored)."""
    from vtsbench.evaluation import leaderboard

    split, part = slip_split(vts_dataset)
    root = tmp_path / "lb"
    add_entries(vts_dataset, tmp_path, root, split, part, ("old-good", "new-worse"))
    folder = root / load_info(vts_dataset).name / split
    for p in folder.glob("new-worse-*.json"):
        doc = json.loads(p.read_text())
        doc["dataset"]["dataset_version"] = "2.0.0"
        p.write_text(json.dumps(doc))
    md = leaderboard.render_folder(folder)
    ranked, _, earlier = md.partition("## Scored on an earlier dataset version")
    assert "Dataset version 2.0.0: 1 entries" in ranked and "| new-worse |" in ranked
    assert "old-good" not in ranked
    assert "| 1.0.0 | old-good |" in earlier and "version 2.0.0 is current" in earlier
    key = leaderboard._version_key
    assert key("2.0.0") > key("2.0.0-rc1") > key("1.10.0") > key("1.9.0")
    assert key("2.0.0+demo") == key("2.0.0")
