"""Finished training runs: the config a run trained with is read back from its folder, and a
folder without one is refused in one line naming it."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from vtsbench.cli import app
from vtsbench.errors import VtsError
from vtsbench.recipes.runs import CONFIG_NAME, finish_run, read_run_config


def test_the_config_of_a_run_trained_with_vtsbench_train(vts_dataset: Path, toy_file: Path,
                                                          tmp_path: Path) -> None:
    cfg = tmp_path / "cfg.json"
    cfg.write_text(json.dumps({"direction": 5}))
    out = tmp_path / "run"
    res = CliRunner().invoke(app, ["train", str(toy_file), "--dataset", str(vts_dataset),
                                   "--split", "unseen_objects", "--out", str(out), "--config",
                                   str(cfg), "--quiet"])
    assert res.exit_code == 0, res.output
    # the recipe's default config with the file's key over it
    assert read_run_config(out) == {"state": "slip", "direction": 5}
    assert read_run_config(str(out)) == json.loads((out / CONFIG_NAME).read_text())


def test_finish_run_then_read_it_back(tmp_path: Path) -> None:
    config = {"steps": 3, "lr": 0.001, "crop_px": None, "modality": "rgbd", "frames": [0, 4]}
    assert finish_run(tmp_path, config) == tmp_path / CONFIG_NAME
    assert read_run_config(tmp_path) == config


def test_a_folder_without_a_config_is_not_a_finished_run(tmp_path: Path) -> None:
    out = tmp_path / "half-trained"
    out.mkdir()
    (out / "checkpoint.safetensors").write_bytes(b"")  # checkpoints, but never finished
    with pytest.raises(VtsError, match=re.escape(CONFIG_NAME)) as e:
        read_run_config(out)
    assert str(e.value).startswith(f"{out}: ") and "\n" not in str(e.value)
    assert e.value.path == str(out)
    with pytest.raises(VtsError, match=r"no config\.json"):
        read_run_config(tmp_path / "missing")
