"""The ResNet-50 recipe: a few training steps at a small size, predict, eval and Grad-CAM."""

from __future__ import annotations

import json
from pathlib import Path

from tests.fixtures.data import ROOT
from tests.fixtures.submissions import predict_and_eval
from vtsbench.recipes import load_recipe

RECIPE = ROOT / "vtsbench" / "recipes" / "builtin" / "resnet.py"
SPLIT = "static_sessions"
TINY = {"image_size": 32, "steps": 2, "batch_size": 2, "warmup_steps": 0,
        "checkpoint_every": 1, "gradcam": 2}


def test_resnet_cli_train_predict_eval(vts_dataset: Path, tmp_path: Path) -> None:
    from PIL import Image
    from typer.testing import CliRunner

    import vtsbench
    from vtsbench.cli import app

    cfg = tmp_path / "tiny.json"
    # resnet18: its checkpoints (weights and Adam state) are 140 MB against resnet50's 280 MB
    cfg.write_text(json.dumps({**TINY, "arch": "resnet18"}))
    runner = CliRunner()
    out = tmp_path / "run"
    res = runner.invoke(app, ["train", str(RECIPE), "--dataset", str(vts_dataset), "--split",
                              SPLIT, "--out", str(out), "--config", str(cfg), "--quiet"])
    assert res.exit_code == 0, res.output
    ckpt = out / "checkpoint.safetensors"
    assert ckpt.is_file()
    test_ids = vtsbench.load(vts_dataset).split(SPLIT, "test").ids
    pngs = sorted((out / "gradcam").glob("*.png"))
    assert len(pngs) == min(2, len(test_ids)) > 0
    assert Image.open(pngs[0]).size == (32, 32)
    doc = predict_and_eval("resnet", ckpt, vts_dataset, SPLIT, tmp_path, "resnet")
    assert set(doc["tasks"]) == {"object"}


def test_resnet_depth_predicts_every_sample(vts_dataset: Path, tmp_path: Path) -> None:
    import vtsbench

    rec = load_recipe(RECIPE)
    config = {**rec.default_config(), **TINY, "modality": "depth", "steps": 1, "gradcam": 0,
              "tta": True}
    ckpt = rec.train(vts_dataset, SPLIT, tmp_path, config, progress=False)
    assert not (tmp_path / "gradcam").exists()
    rows = rec.predict(ckpt, vts_dataset, SPLIT, "train")
    ds = vtsbench.load(vts_dataset)
    assert [r["sample_id"] for r in rows] == list(ds.split(SPLIT, "train").ids)
    assert all(0 <= r["pred"] < len(ds.info.objects) for r in rows)


def test_dihedral_views_are_the_eight_exact_symmetries() -> None:
    import torch

    from vtsbench.recipes.builtin.resnet import dihedral_views

    x = torch.arange(2 * 5 * 5, dtype=torch.float32).view(1, 2, 5, 5)  # no symmetry of its own
    v = dihedral_views(x)
    assert v.shape == (8, 2, 5, 5)
    assert len({tuple(t.flatten().tolist()) for t in v}) == 8  # all different
    for t in v:  # each a rearrangement of the same pixels, channels kept together
        assert torch.equal(t.flatten(1).sort(1).values, x[0].flatten(1).sort(1).values)
    assert torch.equal(v[0], x[0]) and torch.equal(v[4], x[0].flip(-1))


def test_depth_detail_lifts_fine_relief_and_leaves_a_smooth_dome() -> None:
    import torch

    from vtsbench.recipes.builtin.resnet import _normalize

    yy, xx = torch.meshgrid(torch.arange(64.0), torch.arange(64.0), indexing="ij")
    dome = (0.5 * torch.exp(-((xx - 32) ** 2 + (yy - 32) ** 2) / (2 * 12.0**2))).view(1, 1, 64, 64)
    weave = 0.01 * torch.sign(torch.sin(xx * torch.pi / 2)).view(1, 1, 64, 64)  # period 4 px
    cfg = {"modality": "depth", "depth_scale_mm": 0.5}
    assert torch.equal(_normalize(dome + weave, cfg), (dome + weave) / 0.5)  # off: a plain scale
    on = {**cfg, "depth_detail_gain": 10.0, "depth_detail_px": 2.0}
    smooth = _normalize(dome, on) - dome / 0.5
    # the dome (peak 1.0 in units of depth_scale_mm) bends by its curvature only: 0.27 at most
    assert smooth[..., 8:-8, 8:-8].abs().max() < 0.3
    lifted = _normalize(dome + weave, on) - _normalize(dome, on)
    # the weave's 0.02 amplitude (in units of depth_scale_mm) comes out about 10x larger
    assert 0.15 < float(lifted[..., 8:-8, 8:-8].std()) < 0.3
    assert float((weave / 0.5)[..., 8:-8, 8:-8].std()) < 0.025
