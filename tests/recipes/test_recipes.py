"""Recipe loading (file path, entry point, built-in name), configs and submission writing."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.fixtures.data import ROOT
from tests.fixtures.recipes import TOY
from vtsbench.errors import VtsError
from vtsbench.recipes import Recipe, load_config, load_recipe, registered


def test_load_from_path(toy_file: Path) -> None:
    rec = load_recipe(toy_file)
    assert isinstance(rec, Recipe) and rec.name == "toy"
    assert load_recipe(str(toy_file)).default_config() == {"state": "slip", "direction": 2}


def test_load_errors(tmp_path: Path) -> None:
    with pytest.raises(VtsError, match="not found"):
        load_recipe(tmp_path / "nope.py")
    bad = tmp_path / "bad.py"
    bad.write_text("X = 1\n")
    with pytest.raises(VtsError, match="no RECIPE"):
        load_recipe(bad)
    half = tmp_path / "half.py"
    half.write_text("class R:\n    name = 'r'\nRECIPE = R()\n")
    with pytest.raises(VtsError, match="missing tasks"):
        load_recipe(half)
    with pytest.raises(VtsError, match="unknown recipe 'no-such-recipe'"):
        load_recipe("no-such-recipe")


def test_entry_point_registration(tmp_path: Path, toy_file: Path,
                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """A third-party package registers a recipe under the group vtsbench.recipes."""
    pkg = tmp_path / "site"
    (pkg / "toypkg").mkdir(parents=True)
    (pkg / "toypkg" / "__init__.py").write_text(TOY)
    dist = pkg / "toypkg-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: toypkg\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text("[vtsbench.recipes]\ntoy = toypkg:RECIPE\n")
    monkeypatch.syspath_prepend(str(pkg))
    assert "toy" in registered()
    rec = load_recipe("toy")
    assert rec.name == "toy" and rec.tasks == ("state", "direction")


def test_builtin_name_and_pyproject_entry() -> None:
    assert load_recipe("flow").name == "flow"
    text = (ROOT / "pyproject.toml").read_text()
    assert '[project.entry-points."vtsbench.recipes"]' in text
    assert 'flow = "vtsbench.recipes.builtin.flow:RECIPE"' in text
    assert 'include = ["vtsbench*"]' in text


def test_config_override(toy_file: Path, tmp_path: Path) -> None:
    rec = load_recipe(toy_file)
    assert load_config(rec, None) == {"state": "slip", "direction": 2}
    js = tmp_path / "c.json"
    js.write_text(json.dumps({"direction": 5}))
    assert load_config(rec, js) == {"state": "slip", "direction": 5}
    toml = tmp_path / "c.toml"
    toml.write_text('state = "press"\n')
    assert load_config(rec, toml)["state"] == "press"
    js.write_text(json.dumps({"lr": 1}))
    with pytest.raises(VtsError, match="unknown config keys"):
        load_config(rec, js)
    with pytest.raises(VtsError, match="not found"):
        load_config(rec, tmp_path / "missing.json")


@pytest.mark.parametrize("name", ["resnet", "timesformer"])
def test_config_null_only_where_the_recipe_allows_it(name: str, tmp_path: Path) -> None:
    # the results profile's configs give threads null (torch's default) and the real-video run
    # crop_px null (the whole frame); a null step count is still an error
    rec = load_recipe(name)
    js = tmp_path / "c.json"
    js.write_text(json.dumps({"threads": None, "crop_px": None}))
    cfg = load_config(rec, js)
    assert cfg["threads"] is None and cfg["crop_px"] is None
    js.write_text(json.dumps({"steps": None}))
    with pytest.raises(VtsError, match="'steps': expected a int"):
        load_config(rec, js)
    js.write_text(json.dumps({"steps": True}))  # a bool is not a count
    with pytest.raises(VtsError, match="'steps'"):
        load_config(rec, js)
    js.write_text(json.dumps({"pretrained_path": "w"}))  # a null default takes any value
    assert load_config(rec, js)["pretrained_path"] == "w"
    if name == "timesformer":  # pretrained: null (the config decides), true or false
        js.write_text(json.dumps({"pretrained": False}))
        assert load_config(rec, js)["pretrained"] is False


def test_cli_train_predict_eval_with_a_file_recipe(vts_dataset: Path, toy_file: Path,
                                                   tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from vtsbench.cli import app

    runner = CliRunner()
    cfg = tmp_path / "cfg.json"
    cfg.write_text(json.dumps({"state": "static"}))
    res = runner.invoke(app, ["train", str(toy_file), "--dataset", str(vts_dataset), "--split",
                              "unseen_objects", "--out", str(tmp_path / "run"), "--config",
                              str(cfg), "--quiet"])
    assert res.exit_code == 0, res.output
    assert json.loads((tmp_path / "run" / "config.json").read_text())["state"] == "static"
    # a failed train (here a split the dataset does not have) leaves no run folder behind
    res = runner.invoke(app, ["train", "flow", "--dataset", str(vts_dataset), "--split",
                              "no_such_split", "--out", str(tmp_path / "failed"), "--quiet"])
    assert res.exit_code == 2, res.output
    assert not (tmp_path / "failed").exists()
    sub = tmp_path / "toy.csv"
    res = runner.invoke(app, ["predict", str(toy_file), str(tmp_path / "run" / "toy.json"),
                              "--dataset", str(vts_dataset), "--split", "unseen_objects",
                              "--out", str(sub), "--method", "toy baseline"])
    assert res.exit_code == 0, res.output
    meta = json.loads((tmp_path / "toy.meta.json").read_text())
    assert meta["method"] == "toy baseline" and meta["dataset_version"] == "1.0.0"
    res = runner.invoke(app, ["eval", str(sub), "--dataset", str(vts_dataset), "--split",
                              "unseen_objects"])
    assert res.exit_code == 0, res.output
    assert "toy baseline" in res.output
    res = runner.invoke(app, ["predict", str(toy_file), str(tmp_path / "nope.json"),
                              "--dataset", str(vts_dataset), "--split", "unseen_objects",
                              "--out", str(sub)])
    assert res.exit_code == 2
