"""A split a lab gives (`build --holdout-objects`) goes through train, predict and eval."""

from __future__ import annotations

from pathlib import Path

from tests.fixtures.data import ROOT
from tests.fixtures.submissions import predict_and_eval

FLOW = ROOT / "vtsbench" / "recipes" / "builtin" / "flow.py"


def test_given_objects_through_train_predict_eval(vts_dataset: Path, tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from vtsbench.cli import app
    from vtsbench.dataset.read.loader import load

    rec = vts_dataset.parent / "recordings"
    objects = sorted(set(load(vts_dataset).slip.index.column("object").to_pylist()))
    (tmp_path / "held.txt").write_text(objects[0] + "\n")
    ds = tmp_path / "ds"
    runner = CliRunner()
    res = runner.invoke(app, ["build", str(rec), str(ds), "--quiet", "--shard-mb", "1",
                              "--holdout-objects", str(tmp_path / "held.txt")])
    assert res.exit_code == 0, res.output
    test = load(ds).slip.split("given_objects", "test")
    assert set(test.index.column("object").to_pylist()) == {objects[0]}
    res = runner.invoke(app, ["train", str(FLOW), "--dataset", str(ds), "--split",
                              "given_objects", "--out", str(tmp_path / "run"), "--quiet"])
    assert res.exit_code == 0, res.output
    doc = predict_and_eval(str(FLOW), tmp_path / "run" / "checkpoint.safetensors", ds,
                           "given_objects", tmp_path, "flow")
    assert doc["split"] == "given_objects" and "state" in doc["tasks"]
