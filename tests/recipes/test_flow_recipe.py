"""The optical-flow baseline: features, fitted thresholds, checkpoint and the CLI end to end."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from tests.fixtures.data import ROOT
from tests.fixtures.submissions import predict_and_eval
from vtsbench.labels import angle_to_class
from vtsbench.recipes import load_recipe

FLOW = ROOT / "vtsbench" / "recipes" / "builtin" / "flow.py"


def _shifted(dx: int, dy_rows: int, frames: int = 5) -> np.ndarray:
    """A textured image moving by (dx, dy_rows) pixels per frame (rows point down)."""
    rng = np.random.default_rng(0)
    base = rng.integers(0, 255, size=(120, 160), dtype=np.uint8)
    import cv2

    base = cv2.GaussianBlur(base, (0, 0), 2.0)
    out = []
    for t in range(frames):
        m = np.float32([[1, 0, dx * t], [0, 1, dy_rows * t]])
        f = cv2.warpAffine(base, m, (160, 120), borderMode=cv2.BORDER_REFLECT)
        out.append(np.repeat(f[:, :, None], 3, axis=2))
    return np.stack(out)


@pytest.mark.parametrize(("dx", "dy_rows", "cls"), [(2, 0, 0), (0, -2, 2), (-2, 0, 4),
                                                    (0, 2, 6), (2, -2, 1), (-2, 2, 5)])
def test_direction_follows_the_project_convention(dx: int, dy_rows: int, cls: int) -> None:
    """y up: a motion up the image (rows decreasing) is class 2."""
    mod = load_recipe(FLOW)
    import sys

    flow_mod = sys.modules[type(mod).__module__]
    feats, angle = flow_mod.flow_features(flow_mod.sequence_flow(_shifted(dx, dy_rows)))
    assert angle_to_class(angle) == cls
    assert feats[2] > 1.0  # net translation of about 2 px per frame
    assert feats[3] > 0.5  # coherent motion


def test_features_combine_each_pair_and_the_percentile_is_numpys() -> None:
    """The features are combined from per-pair statistics (what the monitor keeps from one
    window to the next): the means over every pixel, and a 90th percentile of the magnitude
    found from histograms that equals numpy's over all pairs at once."""
    from vtsbench.recipes.builtin import flow as flow_mod

    rng = np.random.default_rng(3)
    flows = [flow_mod.sequence_flow(_shifted(2, -1)),
             rng.normal(0, 2, (7, 30, 40, 2)).astype(np.float32),
             np.zeros((3, 20, 20, 2), np.float32),  # a still gel: all zero
             np.round(rng.normal(0, 1, (4, 25, 30, 2))).astype(np.float32)]  # many ties
    flows[2][1, 3, 4] = (0.5, 0.0)
    for flow in flows:
        feats, angle = flow_mod.flow_features(flow)
        fx, fy = flow[..., 0].astype(np.float64), flow[..., 1].astype(np.float64)
        mag = np.hypot(flow[..., 0], flow[..., 1])
        assert feats[1] == pytest.approx(float(np.percentile(mag, 90)), rel=1e-6, abs=1e-12)
        assert feats[0] == pytest.approx(mag.mean(dtype=np.float64), rel=1e-9, abs=1e-12)
        net = math.hypot(fx.mean(), fy.mean())
        assert feats[2] == pytest.approx(net, rel=1e-9, abs=1e-12)
        div = np.gradient(fx, axis=2) + np.gradient(fy, axis=1)
        assert feats[4] == pytest.approx(div.mean(), rel=1e-6, abs=1e-9)
        assert feats[5] == pytest.approx(np.abs(div).mean(), rel=1e-6, abs=1e-9)
        assert 0 <= angle < 360


def test_the_global_shift_leaves_the_grey_frames_it_is_given_as_they_were() -> None:
    """OpenCV's phaseCorrelate windows its inputs in place: the frames a stream keeps from one
    window to the next must come back unchanged, and give the shift of fresh ones."""
    from vtsbench.recipes.builtin import flow as flow_mod

    rgb = _shifted(2, 1, frames=6)
    for slope in (False, True):
        grey = [g.astype(np.float32) for g in flow_mod._gray(rgb, 1.0)]
        kept = [g.copy() for g in grey]
        got = flow_mod.global_shift(rgb, 1.0, slope, grey)
        assert all(np.array_equal(a, b) for a, b in zip(grey, kept, strict=True))
        assert got == flow_mod.global_shift(rgb, 1.0, slope)
        assert got[0] > 5 and got[1] > 2  # about 10 and 5 px over the 6 frames


def test_flow_cli_end_to_end(vts_dataset: Path, tmp_path: Path) -> None:
    from safetensors import safe_open
    from typer.testing import CliRunner

    from vtsbench.cli import app

    runner = CliRunner()
    out = tmp_path / "run"
    res = runner.invoke(app, ["train", str(FLOW), "--dataset", str(vts_dataset), "--split",
                              "unseen_objects", "--out", str(out), "--quiet"])
    assert res.exit_code == 0, res.output
    ckpt = out / "checkpoint.safetensors"
    with safe_open(str(ckpt), framework="numpy") as fh:
        meta = fh.metadata()
        thresholds = fh.get_tensor("tree.threshold")
    assert meta["recipe"] == "flow" and json.loads(meta["config"])["preset"] == "fast"
    assert np.isfinite(thresholds).all()
    doc = predict_and_eval(str(FLOW), ckpt, vts_dataset, "unseen_objects", tmp_path, "flow")
    assert set(doc["tasks"]) == {"state", "direction"}


def test_flow_directions_well_above_chance(vts_dataset: Path, tmp_path: Path) -> None:
    """Every slip sequence of the test dataset (all parts): direction from the mean flow."""
    import vtsbench

    rec = load_recipe("flow")
    ckpt = rec.train(vts_dataset, "unseen_objects", tmp_path, rec.default_config(),
                     progress=False)
    ds = vtsbench.load(vts_dataset)
    hits = total = 0
    for part in ds.parts("unseen_objects"):
        view = ds.split("unseen_objects", part)
        truth = dict(zip(view.ids, view.index["direction"].to_pylist(), strict=True))
        for r in rec.predict(ckpt, vts_dataset, "unseen_objects", part):
            if r["task"] == "direction" and truth[r["sample_id"]] is not None:
                total += 1
                hits += r["pred"] == truth[r["sample_id"]]
    assert total >= 3
    assert hits / total > 3 / 8  # chance is 1/8
    assert math.isfinite(float(np.median(rec.latency_s)))


def _imprint_over_fixed_pattern(dx: int, dy_rows: int, frames: int = 6, lost_at: int | None = None
                                ) -> tuple[np.ndarray, np.ndarray]:
    """A textured disc (the imprint) moving by (dx, dy_rows) px a frame over a strong fixed
    pattern that does not move, and its contact masks; contact lost from frame `lost_at`."""
    import cv2

    rng = np.random.default_rng(1)
    pattern = cv2.GaussianBlur(rng.integers(0, 255, (120, 160), dtype=np.uint8), (0, 0), 1.0)
    texture = cv2.GaussianBlur(rng.integers(0, 255, (120, 160), dtype=np.uint8), (0, 0), 1.5)
    yy, xx = np.mgrid[0:120, 0:160]
    out, masks = [], []
    for t in range(frames):
        cx, cy = 70 + dx * t, 60 + dy_rows * t
        m = (xx - cx) ** 2 + (yy - cy) ** 2 < 20 ** 2
        if lost_at is not None and t >= lost_at:
            m[:] = False
        tex = cv2.warpAffine(texture, np.float32([[1, 0, dx * t], [0, 1, dy_rows * t]]),
                             (160, 120), borderMode=cv2.BORDER_REFLECT)
        f = pattern.astype(np.float32) * 0.8
        f[m] = 0.1 * f[m] + 0.9 * tex[m]  # the imprint outshines the pattern under it
        out.append(np.repeat(np.clip(f, 0, 255).astype(np.uint8)[:, :, None], 3, axis=2))
        masks.append(m)
    return np.stack(out), np.stack(masks)


@pytest.mark.parametrize(("dx", "dy_rows", "cls"), [(1, 0, 0), (0, -1, 2), (-1, 1, 5)])
def test_contact_direction_reads_the_imprint_not_the_fixed_pattern(dx: int, dy_rows: int,
                                                                    cls: int) -> None:
    """The `contact` rule follows the imprint over a fixed pattern that holds a whole-frame
    phase correlation at zero; frames out of contact at the end are left out; without a
    contact mask the phase rule decides."""
    import sys

    import cv2

    flow_mod = sys.modules[type(load_recipe(FLOW)).__module__]
    rgb, contact = _imprint_over_fixed_pattern(dx, dy_rows)
    g = [cv2.cvtColor(f, cv2.COLOR_RGB2GRAY).astype(np.float32) for f in (rgb[0], rgb[-1])]
    (sx, sy), _ = cv2.phaseCorrelate(g[0], g[1])
    assert math.hypot(sx, sy) < 1.0  # the registration locks onto the fixed pattern
    cfg = {**load_recipe(FLOW).default_config()}
    assert cfg["direction"] == "contact"
    _, angle = flow_mod.sequence_features(rgb, cfg, contact)
    assert angle_to_class(angle) == cls
    def off_deg(u: float, v: float) -> float:
        return abs((math.degrees(math.atan2(v, u) - math.atan2(dy_rows, dx)) + 180) % 360 - 180)

    dxm, dym, ratio, centroid = flow_mod.contact_motion(rgb, contact)
    # the direction is what the rule is for; its length is diluted by the gel the imprint
    # uncovers (inside the union of the two masks, outside the moved imprint)
    assert off_deg(dxm, dym) < 10 and math.hypot(dxm, dym) / (5 * math.hypot(dx, dy_rows)) > 0.4
    assert 0.8 < ratio < 1.25 and abs(centroid - 5 * math.hypot(dx, dy_rows)) < 0.5
    # contact lost after frame 3 (a few pixels of mask left, as a build's contact mask keeps):
    # the motion is measured from frame 0 to frame 3
    rgb, contact = _imprint_over_fixed_pattern(dx, dy_rows, lost_at=4)
    contact[4:, 0, :3] = True
    assert flow_mod.contact_frames(contact) == [0, 1, 2, 3]
    dxm, dym, _, _ = flow_mod.contact_motion(rgb, contact)
    assert off_deg(dxm, dym) < 10 and math.hypot(dxm, dym) < 3.5 * math.hypot(dx, dy_rows)
    # a mask over the whole frame is a change of light, not a contact
    whole = contact.copy()
    whole[0] = True
    assert flow_mod.contact_frames(whole) == [1, 2, 3]
    # no mask, or one frame in contact: no contact motion (the phase rule decides)
    assert flow_mod.contact_motion(rgb, None) is None
    assert flow_mod.contact_motion(rgb, contact * (np.arange(6) < 1)[:, None, None]) is None
