"""Scoring reads the dataset only through `vtsbench.load`: a submission scored against the
dataset given as a file:// URL or over HTTP gets the folder's scores byte for byte, and the
leaderboard adds and re-scores from a URL."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.fixtures.submissions import slip_split, write_submission
from vtsbench.errors import VtsError
from vtsbench.evaluation import leaderboard
from vtsbench.evaluation.report import evaluate_submission
from vtsbench.evaluation.submission import load_truth


@pytest.mark.parametrize("where", ["file", "http"])
def test_eval_of_a_url_equals_the_folder(vts_dataset: Path, tmp_path: Path, where: str,
                                         request: pytest.FixtureRequest) -> None:
    split, part = slip_split(vts_dataset)
    sub = write_submission(vts_dataset, tmp_path / "sub", split, part, wrong=1)
    url = vts_dataset.as_uri() if where == "file" else request.getfixturevalue("http_root")
    assert url.startswith("file://" if where == "file" else "http://")
    folder, _, _ = evaluate_submission(sub, vts_dataset, split, part, out=tmp_path / "folder",
                                       figures=False)
    scored, _, _ = evaluate_submission(sub, url, split, part, out=tmp_path / "url",
                                       figures=False)
    assert scored == folder
    d = scored.tasks["direction"].first.direction
    assert d is not None and d.by_magnitude is not None  # the slip index read from the URL
    assert sum(b.n for b in d.by_magnitude.bins) > 0
    for name in ("metrics.json", "report.md"):
        assert (tmp_path / "url" / name).read_bytes() == \
            (tmp_path / "folder" / name).read_bytes(), name


def test_leaderboard_add_and_rescore_from_a_file_url(vts_dataset: Path, tmp_path: Path) -> None:
    split, part = slip_split(vts_dataset)
    sub = write_submission(vts_dataset, tmp_path / "sub", split, part, wrong=1)
    url = vts_dataset.as_uri()
    root = tmp_path / "lb"
    path = leaderboard.add(sub, url, split, part, root=root)
    before = json.loads(path.read_text())
    assert leaderboard.rescore(root, url, force=True) == [path]
    after = json.loads(path.read_text())
    assert after["metrics"] == before["metrics"] and after["rescored_from"] == []


def test_a_split_missing_from_a_url_names_the_url(vts_dataset: Path) -> None:
    url = vts_dataset.as_uri()
    with pytest.raises(VtsError) as e:
        load_truth(url, "no-such-split")
    assert str(e.value).startswith(f"{url}: no split 'no-such-split'")


def test_the_eval_command_scores_a_file_url(vts_dataset: Path, tmp_path: Path) -> None:
    """`vtsbench eval --dataset file://...` keeps the URL as given (a Path makes it file:/x)."""
    from typer.testing import CliRunner

    from vtsbench.cli import app

    split, part = slip_split(vts_dataset)
    sub = write_submission(vts_dataset, tmp_path / "sub", split, part, wrong=1)
    runner = CliRunner()
    for name, where in (("url", vts_dataset.as_uri()), ("folder", str(vts_dataset))):
        res = runner.invoke(app, ["eval", str(sub), "--dataset", where, "--split", split,
                                  "--part", part, "--out", str(tmp_path / name),
                                  "--no-figures"])
        assert res.exit_code == 0, res.output
    assert (tmp_path / "url" / "metrics.json").read_bytes() == \
        (tmp_path / "folder" / "metrics.json").read_bytes()
