"""The TimeSformer recipe: a few training steps of a tiny model, then predict and eval."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.fixtures.data import ROOT
from tests.fixtures.submissions import predict_and_eval
from vtsbench.errors import VtsError
from vtsbench.recipes import load_recipe

RECIPE = ROOT / "vtsbench" / "recipes" / "builtin" / "timesformer.py"
TINY = {"config": "small", "modality": "rgbd", "image_size": 32, "num_frames": 2, "steps": 3,
        "batch_size": 2, "warmup_steps": 0, "checkpoint_every": 2}


def test_timesformer_cli_train_predict_eval(vts_dataset: Path, tmp_path: Path) -> None:
    from safetensors import safe_open
    from typer.testing import CliRunner

    from vtsbench.cli import app

    cfg = tmp_path / "tiny.json"
    cfg.write_text(json.dumps(TINY))
    runner = CliRunner()
    out = tmp_path / "run"
    res = runner.invoke(app, ["train", str(RECIPE), "--dataset", str(vts_dataset), "--split",
                              "unseen_objects", "--out", str(out), "--config", str(cfg),
                              "--quiet"])
    assert res.exit_code == 0, res.output
    ckpt = out / "checkpoint.safetensors"
    with safe_open(str(ckpt), framework="pt") as fh:
        meta = fh.metadata()
        assert fh.get_tensor("model.state_head.weight").shape[0] == 3
    assert meta["recipe"] == "timesformer" and meta["step"] == "3"
    assert json.loads(meta["recipe_config"])["modality"] == "rgbd"
    doc = predict_and_eval("timesformer", ckpt, vts_dataset, "unseen_objects", tmp_path, "tsf")
    assert set(doc["tasks"]) == {"state", "direction"}


def test_timesformer_rows_for_every_sample(vts_dataset: Path, tmp_path: Path) -> None:
    import vtsbench

    rec = load_recipe(RECIPE)
    config = {**rec.default_config(), **TINY, "modality": "depth", "steps": 1}
    ckpt = rec.train(vts_dataset, "unseen_objects", tmp_path, config, progress=False)
    rows = rec.predict(ckpt, vts_dataset, "unseen_objects", "val")
    ids = vtsbench.load(vts_dataset).split("unseen_objects", "val").ids
    assert [r["sample_id"] for r in rows if r["task"] == "state"] == list(ids)
    assert [r["sample_id"] for r in rows if r["task"] == "direction"] == list(ids)
    assert all(0 <= r["pred"] < 8 for r in rows if r["task"] == "direction")


def test_delta_input_and_input_modes() -> None:
    import torch

    from vtsbench.recipes.builtin.timesformer import _normalize, input_mode

    x = torch.rand(2, 4, 3, 8, 8)
    small = {"config": "small", "modality": "rgb", "depth_scale_mm": 1.0, "input": None,
             "delta_gain": 4.0}
    assert input_mode(small) == "frames+delta"
    assert input_mode({**small, "config": "paper"}) == "frames+delta"
    both = _normalize(x, small)
    assert both.shape == (2, 4, 6, 8, 8)
    assert torch.equal(both[:, :, :3], (x - 0.5) / 0.5)
    small["input"] = "delta"
    d = _normalize(x, small)
    assert torch.equal(both[:, :, 3:], d)
    assert torch.equal(d[:, 0], torch.zeros_like(d[:, 0]))  # the first frame minus itself
    assert torch.allclose(d, ((x - x[:, :1]) * 8).clamp(-1, 1), atol=1e-6)
    assert torch.equal(_normalize(x, {**small, "input": "frames"}), (x - 0.5) / 0.5)
    with pytest.raises(VtsError, match="input"):
        input_mode({**small, "input": "optical"})
    with pytest.raises(VtsError, match="crop_px"):
        input_mode({**small, "input": "frames+flow", "crop_px": None})
    crop = {**small, "input": "frames+delta+flow", "crop_px": 16}
    x5 = torch.rand(2, 4, 5, 8, 8)
    out = _normalize(x5, crop)
    assert out.shape == (2, 4, 8, 8, 8)
    assert torch.equal(out[:, :, 6:], x5[:, :, 3:]) and torch.equal(out[:, :, :3],
                                                                    (x5[:, :, :3] - 0.5) / 0.5)
    # the default on crops: each frame's difference to the first, then the motion channels
    crop = {**small, "input": None, "crop_px": 16}
    assert input_mode(crop) == "delta+flow"
    out = _normalize(x5, crop)
    assert out.shape == (2, 4, 5, 8, 8)
    assert torch.equal(out[:, :, :3], _normalize(x5[:, :, :3], {**small, "input": "delta"}))
    assert torch.equal(out[:, :, 3:], x5[:, :, 3:])


def test_slip_oversample_must_be_positive(vts_dataset: Path, tmp_path: Path) -> None:
    rec = load_recipe(RECIPE)
    config = {**rec.default_config(), **TINY, "slip_oversample": 0}
    with pytest.raises(VtsError, match="slip_oversample"):
        rec.train(vts_dataset, "unseen_objects", tmp_path, config, progress=False)
