"""Marker gels: dots found in the background and in each frame, left out of the fit, filled in
the gradients before integration; checked on simulated presses with a printed grid multiplied
on, against the exact truth of the same presses without it."""

from __future__ import annotations

import importlib.util
import shutil
from pathlib import Path

import numpy as np
import pytest

from tests.test_calibration_data import MM_PER_PX, sim_folder
from vtsbench.depth.calibration import calibrate, load_calibration, save_calibration
from vtsbench.depth.markers import detect_markers, fill_gradients, marker_mask
from vtsbench.depth.reconstruct import reconstruct
from vtsbench.recordings.manifest import load_manifest
from vtsbench.recordings.media import read_image, write_png


def dot_layer(h: int, w: int, mm: float, pitch: float = 1.2, diameter: float = 0.42,
              darkness: float = 0.7, edge: float = 0.08) -> np.ndarray:
    """Transmission (H, W) of a printed grid of soft dark dots (pitch, diameter in mm)."""
    y, x = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
    p = pitch / mm
    dx, dy = ((x / p + 0.3) % 1 - 0.5) * p, ((y / p + 0.6) % 1 - 0.5) * p
    t = np.clip((np.hypot(dx, dy) * mm - (diameter / 2 - edge / 2)) / edge, 0, 1)
    return 1 - darkness * (1 - t)


@pytest.fixture(scope="module")
def folders(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, np.ndarray]:
    """The simulated presses, and the same with a dot grid multiplied on frames and background."""
    plain = sim_folder(tmp_path_factory)
    marked = tmp_path_factory.mktemp("markers") / "sim"
    shutil.copytree(plain, marked)
    m = load_manifest(marked)
    img = read_image(marked / m.entries[0].source.path)
    layer = dot_layer(*img.shape[:2], MM_PER_PX)
    files = {e.source.path for e in m.entries} | {s.background for s in m.sessions
                                                  if s.background}
    for f in files:
        im = read_image(marked / f).astype(np.float64)
        write_png(marked / f, np.clip(np.rint(im * layer[..., None]), 0, 255).astype(np.uint8))
    return plain, marked, layer


def held_rmse(run) -> float:
    return float(np.mean([h.errors["plane_aligned_rmse_mm"] for h in run.held_out]))


def test_marker_gel_depth_within_1_2x_of_the_same_presses_without(folders) -> None:
    plain, marked, _ = folders
    base = calibrate(plain, method="poly", holdout=2, seed=1, device=None)
    run = calibrate(marked, method="poly", holdout=2, seed=1, device=None)
    off = calibrate(marked, method="poly", holdout=2, seed=1, device=None, markers="off")
    assert base.calibration.markers is None  # a markerless gel: nothing found
    spec = run.calibration.markers
    assert spec is not None and spec.n_dots >= 40 and 6 <= spec.diameter_px <= 10
    # scored against the exact truth of the simulated presses (the same with or without dots)
    assert [h.reference for h in run.held_out] == ["truth", "truth"]
    assert held_rmse(run) <= 1.2 * held_rmse(base)
    assert held_rmse(off) > 1.5 * held_rmse(base)  # left in, the dots are learnt as slopes


def test_marker_gel_flat_frame_gives_flat_depth_and_the_file_keeps_the_dots(folders,
                                                                            tmp_path) -> None:
    _, marked, layer = folders
    run = calibrate(marked, method="lut", holdout=2, seed=1, device=None,
                    options={"bins": 24, "cells": 2})
    cal = load_calibration(save_calibration(run.calibration, tmp_path / "m.safetensors"))
    assert cal.markers == run.calibration.markers
    assert cal.metadata()["features"]["markers"]["n_dots"] == cal.markers.n_dots
    assert not np.any(reconstruct(cal.background, cal))  # the background: exactly flat
    if importlib.util.find_spec("torch") is not None:  # the torch path fills the dots too
        img = run.held_out[0].press.image
        np.testing.assert_allclose(reconstruct(img, cal, device="cpu"), reconstruct(img, cal),
                                   atol=2e-4)
    # the gradient error over a press's contact does not follow the dots with the fill; it
    # does with the dots left in the fit (high-passed error against the high-passed dot layer)
    off = calibrate(marked, method="lut", holdout=2, seed=1, device=None, markers="off",
                    options={"bins": 24, "cells": 2})
    held = run.held_out[0]
    assert pattern(run.calibration, held, layer) < 0.5 * pattern(off.calibration, held, layer)


def pattern(cal, held, layer: np.ndarray) -> float:
    """|correlation| of the high-passed slope error over the contact with the dot layer's."""
    from scipy import ndimage

    g = cal.gradients(held.press.image)
    tq, tp = np.gradient(held.true_depth, *cal.mm_per_px[::-1])
    err = np.hypot(g[..., 0] - tp, g[..., 1] - tq)
    hp = err - ndimage.gaussian_filter(err, 3)
    lp = layer - ndimage.gaussian_filter(layer, 3)
    inner = ndimage.binary_erosion(held.region, iterations=3)
    return abs(float(np.corrcoef(hp[inner], lp[inner])[0, 1]))


def test_detect_markers_on_a_grid_and_not_on_plain_gel() -> None:
    rng = np.random.default_rng(3)
    h, w, mm = 120, 160, 0.06
    gel = np.full((h, w, 3), (150, 120, 100), np.float64) + rng.normal(0, 1.5, (h, w, 3))
    shade = np.linspace(0.8, 1.1, w)[None, :, None]  # light falling off across the gel
    plain = np.clip(gel * shade, 0, 255).astype(np.uint8)
    assert detect_markers(plain, mm) is None
    dotted = np.clip(gel * shade * dot_layer(h, w, mm)[..., None], 0, 255).astype(np.uint8)
    spec = detect_markers(dotted, mm)
    assert spec is not None and spec.n_dots >= 40
    m = marker_mask(dotted, spec)
    truth = dot_layer(h, w, mm) < 0.95
    assert m[truth].mean() > 0.98  # every dot pixel masked ...
    assert m.mean() < 2.5 * truth.mean()  # ... and not much else


def test_harmonic_fill_is_exact_on_a_linear_field() -> None:
    y, x = np.mgrid[0:40, 0:50].astype(np.float32)
    g = np.stack([0.01 * x - 0.3, 0.02 * y + 0.005 * x], -1)
    mask = np.zeros((40, 50), bool)
    mask[10:18, 12:20] = mask[25:33, 30:45] = True
    broken = g.copy()
    broken[mask] = 5.0
    out = fill_gradients(broken, mask)
    np.testing.assert_allclose(out, g, atol=2e-5)
    np.testing.assert_array_equal(fill_gradients(g, np.zeros_like(mask)), g)
