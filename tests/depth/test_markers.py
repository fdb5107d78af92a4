"""Marker gels: dots found in the background and in each frame, left out of the fit, filled in
the gradients before integration; checked on simulated presses with a printed grid multiplied
on, against the exact truth of the same presses without it."""

from __future__ import annotations

import importlib.util
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from tests.fixtures.calibration import MM_PER_PX, sim_folder
from tests.fixtures.flow import Flow, unflowed_grid
from vtsbench.depth.calibration import (
    calibrate,
    colour_difference,
    load_calibration,
    metadata_errors,
    save_calibration,
)
from vtsbench.depth.markers import (
    DOT_MIN_TRANSMISSION,
    FIT_MIN_TRANSMISSION,
    corrected,
    detect_markers,
    dot_correction,
    fill_gradients,
    left_out_of_fit,
    marker_mask,
    transmission,
)
from vtsbench.depth.reconstruct import reconstruct
from vtsbench.errors import VtsError
from vtsbench.recordings.manifest import load_manifest
from vtsbench.recordings.media import read_image, write_png


def dot_layer(h: int, w: int, mm: float, pitch: float = 1.2, diameter: float = 0.42,
              darkness: float = 0.7, edge: float = 0.08,
              flow: Flow | None = None) -> np.ndarray:
    """Transmission (H, W) of a printed grid of soft dark dots (pitch, diameter in mm); flow
    (x, y, r, u) px: the dots moved outward by u at the rim of the contact (x, y, r)
    (`unflowed_grid`)."""
    y, x = unflowed_grid(h, w, flow)
    y, x = y + 0.5, x + 0.5
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
    assert not any("recorded with" in w for w in run.warnings)  # PNG: full-resolution colour


def test_a_marker_gel_in_subsampled_colour_is_warned_of(folders, monkeypatch) -> None:
    """Press files whose colour is subsampled (JPEG 4:2:0, most video) get one warning on a
    marker gel, naming a file; a plain gel so recorded gets none (nothing to spread)."""
    import vtsbench.recordings.media as media

    plain, marked, _ = folders
    monkeypatch.setattr(media, "chroma_subsampling", lambda p: "4:2:0")
    kw = {"method": "lut", "holdout": 2, "seed": 1, "device": None,
          "options": {"bins": 16, "cells": 2}}
    notes = [w for w in calibrate(marked, **kw).warnings if "recorded with 4:2:0" in w]
    assert len(notes) == 1 and ".png" in notes[0]
    assert not any("recorded with" in w for w in calibrate(plain, **kw).warnings)


def test_dots_that_move_under_each_press_are_followed(folders, tmp_path, monkeypatch) -> None:
    """The grid moved outward under every press (a tenth of the contact radius at the rim):
    followed, the moved dots leave the held-out depth error within 1.2x of the same presses
    without dots, against exact truth (measured 1.02x); filled whole, the former handling,
    1.39x. (Moved by a fifth, followed 1.38x, filled 1.48x: at the rim a dot then moves more
    than half its size, beyond the following's reach.)"""
    plain, marked, layer = folders
    moved = tmp_path / "moved"
    shutil.copytree(marked, moved)
    m = load_manifest(moved)
    h, w = layer.shape
    for e in m.entries:
        c = e.circle
        flowed = dot_layer(h, w, MM_PER_PX, flow=(c.x, c.y, c.r, 0.1 * c.r))
        im = read_image(plain / e.source.path).astype(np.float64)
        write_png(moved / e.source.path,
                  np.clip(np.rint(im * flowed[..., None]), 0, 255).astype(np.uint8))
    base = held_rmse(calibrate(plain, method="poly", holdout=2, seed=1, device=None))
    run = calibrate(moved, method="poly", holdout=2, seed=1, device=None)
    followed = held_rmse(run)
    frame = run.held_out[0].press.image
    assert run.calibration.dots(frame).offset is not None  # some dots were followed
    # nothing can be followed: moved dots filled whole
    monkeypatch.setattr("vtsbench.depth.markers.FOLLOW_SHARE", -1.0)
    filled = held_rmse(calibrate(moved, method="poly", holdout=2, seed=1, device=None))
    assert followed < filled
    assert followed <= 1.2 * base


def test_dividing_by_the_dots_transmission_gives_the_difference_without_them(folders) -> None:
    plain, marked, layer = folders
    m = load_manifest(marked)
    bg0 = read_image(plain / m.sessions[0].background)
    bg1 = read_image(marked / m.sessions[0].background)
    spec = detect_markers(bg1, MM_PER_PX)
    assert spec is not None
    trans = transmission(bg1, spec)
    semi = layer < 0.9  # every dot pixel: the dots' cores pass 30 % of the light
    np.testing.assert_allclose(trans.mean(axis=-1)[semi], layer[semi], atol=0.06)
    errs, raws = [], []
    for e in m.entries[:4]:
        im0, im1 = read_image(plain / e.source.path), read_image(marked / e.source.path)
        dots = dot_correction(im1, spec, bg1, trans)
        assert not dots.fill[semi].any()  # still dots, none below DOT_MIN_TRANSMISSION: divided
        assert dots.offset is None  # none moved
        d0 = colour_difference(im0, bg0, 0.0)
        changed = semi & (np.abs(d0).max(axis=-1) >= 10)  # on a dot, where the press shows
        errs.append(np.abs(colour_difference(im1, bg1, 0.0, dots=dots) - d0)[changed])
        raws.append(np.abs(colour_difference(im1, bg1, 0.0) - d0)[changed])
    err, raw = np.concatenate(errs), np.concatenate(raws)
    assert err.size > 500
    assert float(np.mean(err)) < 1.5 and float(np.mean(err)) < 0.15 * float(np.mean(raw))


@pytest.mark.parametrize("slide", [2, 5])
def test_a_dot_that_moved_is_followed(folders, slide) -> None:
    """The left half of the grid slid by `slide` px: 2 px, and its dots are followed (the
    frame divided by the shifted transmission, the background's dot-free level taken off), so
    the difference there is the one without dots, not filled; 5 px (more than half a dot), and
    they are filled whole. The right half stays divided as before."""
    plain, marked, layer = folders
    m = load_manifest(marked)
    bg0 = read_image(plain / m.sessions[0].background)
    bg1 = read_image(marked / m.sessions[0].background)
    spec = detect_markers(bg1, MM_PER_PX)
    trans = transmission(bg1, spec)
    im0 = read_image(plain / m.entries[0].source.path)
    w = layer.shape[1]
    moved = layer.copy()
    moved[:, : w // 2] = np.roll(layer, slide, axis=1)[:, : w // 2]
    frame = np.clip(np.rint(im0.astype(np.float64) * moved[..., None]), 0, 255).astype(np.uint8)
    dots = dot_correction(frame, spec, bg1, trans)
    spots = (layer < 0.9) | (moved < 0.9)
    left, right = spots.copy(), spots.copy()
    left[:, w // 2 - 12:] = False  # the dots wholly in either half
    right[:, : w // 2 + 12] = False
    assert dots.fill[right].mean() < 0.01
    if slide > spec.diameter_px / 2:  # the background's dots there: filled whole
        assert dots.fill[left & (layer < 0.9)].mean() > 0.99
        return
    core = (moved < DOT_MIN_TRANSMISSION) | (layer < DOT_MIN_TRANSMISSION)
    assert dots.fill[left & ~core].mean() < 0.05
    d0 = colour_difference(im0, bg0, 0.0)
    raw = np.abs(colour_difference(frame, bg1, 0.0) - d0)[left & ~dots.fill]
    err = np.abs(colour_difference(frame, bg1, 0.0, dots=dots) - d0)[left & ~dots.fill]
    assert float(err.mean()) < 0.2 * float(raw.mean()), (err.mean(), raw.mean())


def test_marker_gel_flat_frame_gives_flat_depth_and_the_file_keeps_the_dots(folders,
                                                                            tmp_path) -> None:
    plain_folder, marked, _ = folders
    run = calibrate(marked, method="lut", holdout=2, seed=1, device=None,
                    options={"bins": 24, "cells": 2})
    cal = load_calibration(save_calibration(run.calibration, tmp_path / "m.safetensors"))
    assert cal.markers == run.calibration.markers
    assert cal.metadata()["features"]["markers"]["n_dots"] == cal.markers.n_dots
    assert metadata_errors(cal.metadata()) == []  # the markers' sub-schema
    assert cal.markers.dot_blur_px > 0  # 0.06 mm/px: the dots get a blur of their own
    bad = cal.metadata()
    bad["features"]["markers"]["dot_blur_px"] = -1.0
    assert metadata_errors(bad)
    from safetensors.numpy import save

    for blur, why in ((float("nan"), "NaN"), (1e9, r"features\.markers out of range")):
        meta = cal.metadata()  # a hostile file: one line, and no Gaussian of 1e9 px
        meta["features"]["markers"]["dot_blur_px"] = blur
        (tmp_path / "bad.st").write_bytes(save(cal.tensors(),
                                               metadata={"vtsbench": json.dumps(meta)}))
        with pytest.raises(VtsError, match=why) as err:
            load_calibration(tmp_path / "bad.st")
        assert "\n" not in str(err.value)
    assert not np.any(reconstruct(cal.background, cal))  # the background: exactly flat
    if importlib.util.find_spec("torch") is not None:  # the torch path fills the dots too
        img = run.held_out[0].press.image
        np.testing.assert_allclose(reconstruct(img, cal, device="cpu"), reconstruct(img, cal),
                                   atol=2e-4)
    # divided back, the dots leave the gradient error over a press's contact as it is on the
    # same gel without them (whose error alone follows this grid by chance: |r| 0.2 on the
    # first press); left in the fit, they add their own (high-passed error differences)
    off = calibrate(marked, method="lut", holdout=2, seed=1, device=None, markers="off",
                    options={"bins": 24, "cells": 2})
    plain = calibrate(plain_folder, method="lut", holdout=2, seed=1, device=None,
                      options={"bins": 24, "cells": 2})
    for k in range(2):
        base = slope_error(plain.calibration, plain.held_out[k])
        added = [added_pattern(slope_error(r.calibration, r.held_out[k]), base,
                               plain.held_out[k].region) for r in (run, off)]
        assert added[0] < 0.65 * added[1]


def slope_error(cal, held) -> np.ndarray:
    """(H, W, 2) error of the calibration's gradients against the exact ones of a press."""
    g = cal.gradients(held.press.image)
    tq, tp = np.gradient(held.true_depth, *cal.mm_per_px[::-1])
    return np.stack([g[..., 0] - tp, g[..., 1] - tq], -1)


def added_pattern(err: np.ndarray, base: np.ndarray, region: np.ndarray) -> float:
    """RMS over the contact of the high-passed difference between two slope errors."""
    from scipy import ndimage

    d = err - base
    hp = d - ndimage.gaussian_filter(d, (3, 3, 0))
    inner = ndimage.binary_erosion(region, iterations=3)
    return float(np.sqrt((hp[inner] ** 2).sum(axis=-1).mean()))


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


def test_the_fit_leaves_out_what_the_run_time_corrects_not_a_dark_lobe_beside_a_dot() -> None:
    """A press's dark blob can be a dot merged with a dark lobe of the imprint (the simulator's
    three coloured lights: 455 of a contact's 2460 px). `marker_mask` of the press takes the
    lobe for part of a dot; `corrected`, what the fit leaves out, takes only what the run time
    divides or fills: the background's dots, where a moved dot went, what is filled."""
    rng = np.random.default_rng(5)
    h, w, mm = 120, 160, 0.06
    gel = np.full((h, w, 3), (150, 120, 100), np.float64) + rng.normal(0, 1.0, (h, w, 3))
    layer = dot_layer(h, w, mm)
    bg = np.clip(gel * layer[..., None], 0, 255).astype(np.uint8)
    spec = detect_markers(bg, mm, grow_px=2)
    assert spec is not None
    base = marker_mask(bg, spec)
    trans = transmission(bg, spec)
    # a dark lobe (0.6 of the light) a little larger than a dot, touching the dot nearest
    # (80, 60)
    ys, xs = np.nonzero(layer == layer.min())
    k = np.argmin(np.hypot(xs - 80, ys - 60))
    r = 0.55 * spec.diameter_px
    cx, cy = xs[k] + spec.diameter_px / 2 + 0.9 * r, ys[k]
    yy, xx = np.mgrid[:h, :w]
    lobe = np.hypot(xx - cx, yy - cy) <= r
    press = np.clip(gel * layer[..., None] * np.where(lobe, 0.6, 1.0)[..., None], 0, 255
                    ).astype(np.uint8)
    merged = marker_mask(press, spec, bg)
    away = lobe & ~base
    assert away.sum() > 20 and merged[away].mean() > 0.9  # the press's blob takes the lobe
    corr = dot_correction(press, spec, bg, trans)
    assert np.array_equal(corr.dots, base)  # the correction carries the dots it was made from
    given = dot_correction(press, spec, bg, trans, base)  # the same with them given
    assert np.array_equal(given.fill, corr.fill) and np.array_equal(given.gain, corr.gain)
    fit_out = corrected(corr)
    # the dot's own pixels stay out; of the lobe only what the run time's following of the
    # dot (pulled by the lobe) divides: here about a third
    assert fit_out[base].all() and fit_out[away].mean() < 0.5
    # dots slid by 3 px (under half a dot) are followed: where they went is left out too
    slid = np.roll(layer, 3, axis=1)
    moved = np.clip(gel * slid[..., None], 0, 255).astype(np.uint8)
    went = (slid < 0.9) & ~base
    assert went.any()
    assert corrected(dot_correction(moved, spec, bg, trans))[went].all()


@pytest.mark.parametrize("darkness", [0.7, 0.9])
def test_the_fit_learns_from_the_dots_lighter_parts_and_their_ring(darkness: float) -> None:
    """`left_out_of_fit`: of what the run time corrects, the fit leaves out a still dot's core
    darker than FIT_MIN_TRANSMISSION, what is filled (a core below DOT_MIN_TRANSMISSION) and
    where a moved dot went; a dot's lighter edge and the ring the dots are grown by stay in."""
    rng = np.random.default_rng(6)
    h, w, mm = 120, 160, 0.06
    gel = np.full((h, w, 3), (150, 120, 100), np.float64) + rng.normal(0, 1.0, (h, w, 3))
    layer = dot_layer(h, w, mm, darkness=darkness)
    bg = np.clip(gel * layer[..., None], 0, 255).astype(np.uint8)
    spec = detect_markers(bg, mm, grow_px=2)
    assert spec is not None
    trans = transmission(bg, spec)
    t = trans.mean(axis=-1)
    press = np.clip(gel * 1.1 * layer[..., None], 0, 255).astype(np.uint8)  # nothing moved
    corr = dot_correction(press, spec, bg, trans)
    out = left_out_of_fit(corr, trans)
    core, edge, ring = (corr.dots & (t < FIT_MIN_TRANSMISSION),
                        corr.dots & (t >= FIT_MIN_TRANSMISSION) & (t < 0.95),
                        corr.dots & (t == 1.0))
    assert core.sum() > 100 and edge.sum() > 50 and ring.sum() > 100
    assert out[core].all() and not out[(edge | ring) & ~corr.fill].any()
    assert not out[~corr.dots].any()
    # the darker dots' cores are filled, and the fill grown by spec.grow_px
    assert corr.fill.any() == (darkness > 1 - DOT_MIN_TRANSMISSION)
    assert out[corr.fill].all() and (edge | ring)[corr.fill].any() == corr.fill.any()
    slid = np.roll(layer, 3, axis=1)  # dots slid by 3 px, followed: where they went stays out
    moved = np.clip(gel * slid[..., None], 0, 255).astype(np.uint8)
    went = (slid < 0.9) & ~corr.dots
    assert went.any() and left_out_of_fit(dot_correction(moved, spec, bg, trans), trans)[went].all()


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


def test_build_depth_of_a_marker_gel_is_the_calibrations(folders) -> None:
    """The dataset build's depth path (DepthMaker) divides, follows and fills the dots as
    Calibration.gradients does; on a plain gel it still takes none of it."""
    import dataclasses

    from vtsbench.dataset.build.shard import depth_and_contact
    from vtsbench.depth.depthmaps import DepthMaker
    from vtsbench.depth.poisson import integrate

    plain_folder, marked, layer = folders
    m = load_manifest(marked)
    press = read_image(plain_folder / m.entries[0].source.path).astype(np.float64)
    moved = layer.copy()
    w = layer.shape[1]
    moved[:, : w // 2] = np.roll(layer, 2, axis=1)[:, : w // 2]  # the left half's dots slid
    slid = np.clip(np.rint(press * moved[..., None]), 0, 255).astype(np.uint8)
    for folder, has_dots in ((marked, True), (plain_folder, False)):
        cal = calibrate(folder, method="lut", holdout=2, seed=1, device=None,
                        options={"bins": 24, "cells": 2}).calibration
        assert (cal.markers is not None) == has_dots
        maker = DepthMaker(cal)
        frames = [read_image(folder / e.source.path) for e in m.entries[:2]]
        for k, img in enumerate([*frames, slid] if has_dots else frames):
            g = cal.gradients(img)
            for solver in ("dct", "dst"):
                want = integrate(g[..., 0], g[..., 1], method=solver, mm_per_px=cal.mm_per_px,
                                 dtype=np.float32)
                got = maker.depth(img, solver)
                assert (maker.fill is not None) == has_dots
                if has_dots:
                    np.testing.assert_allclose(got, want, rtol=0, atol=1e-6)
                else:  # unchanged: bit for bit
                    np.testing.assert_array_equal(got, want)
            if k == 2:  # the slid dots are followed (gain and offset), not filled
                assert cal.dots(img).offset is not None
                assert maker.fill[:, : w // 2 - 12].sum() < 20
                if importlib.util.find_spec("torch") is not None:  # and so on torch
                    np.testing.assert_allclose(reconstruct(img, cal, device="cpu"),
                                               reconstruct(img, cal), atol=2e-4)
            built = depth_and_contact(img[None], cal, "dct")[0][0]
            np.testing.assert_array_equal(built, maker.depth(img, "dct"))
            if has_dots:  # the dots left in the difference show in the depth
                raw = DepthMaker(dataclasses.replace(cal, markers=None)).depth(img, "dct")
                assert float(np.abs(raw - maker.depth(img, "dct")).max()) > 0.02


def test_harmonic_fill_factorises_a_mask_once_and_keeps_few() -> None:
    """A mask seen again (a gel's dots in every frame) reuses its factorised system, with the
    same values as a fresh one; other masks get their own, and only _SYSTEMS_MAX are kept."""
    from vtsbench.depth import markers as mk

    rng = np.random.default_rng(3)
    m = rng.random((40, 50)) < 0.25
    g1, g2 = (rng.normal(size=(40, 50, 2)).astype(np.float32) for _ in range(2))
    first = mk._laplace(m)
    assert mk._laplace(m.copy()) is first  # by content, not identity
    for g in (g1, g2):
        np.testing.assert_array_equal(mk._harmonic(g, m), mk._Laplace(m).solve(g))
    for k in range(mk._SYSTEMS_MAX + 2):
        mk._harmonic(g1, rng.random((40, 50)) < 0.1 + 0.02 * k)
    assert len(mk._SYSTEMS) == mk._SYSTEMS_MAX and mk._laplace(m) is not first


def test_the_dots_own_blur_is_a_fixed_size_in_mm() -> None:
    """The dots' blur is DOT_BLUR_MM in pixels where that is wider than the plain blur, else
    none; a file from before it (no `dot_blur_px`) reads as none, as it was fitted."""
    from vtsbench.depth.markers import DOT_BLUR_MM, MarkerSpec, dot_blur_px

    assert dot_blur_px(0.05, 1.0) == pytest.approx(DOT_BLUR_MM / 0.05)
    assert dot_blur_px((0.05, 0.05), 1.0) == dot_blur_px(0.05, 1.0)
    assert dot_blur_px(DOT_BLUR_MM, 1.0) == 0.0  # 1 px: no wider than the plain blur
    spec = MarkerSpec(diameter_px=9.0, window_px=41, dot_blur_px=2.5)
    assert MarkerSpec.from_dict(spec.to_dict()) == spec
    old = {k: v for k, v in spec.to_dict().items() if k != "dot_blur_px"}
    assert MarkerSpec.from_dict(old).dot_blur_px == 0.0


def test_blur_difference_blends_the_dots_blur_in_by_the_weight() -> None:
    import cv2

    from vtsbench.depth.markers import blur_difference, dot_blur_weight

    rng = np.random.default_rng(0)
    frame = rng.normal(0, 10, (40, 50, 3)).astype(np.float32)
    dots = np.zeros((40, 50), bool)
    dots[10:20, 10:20] = True
    w = dot_blur_weight(dots)
    assert w.shape == (40, 50, 1) and w[15, 15, 0] == pytest.approx(1.0, abs=1e-3)
    assert w[35, 45, 0] == 0.0 and 0 < w[15, 21, 0] < 1  # a soft edge
    sharp = cv2.GaussianBlur(frame, (0, 0), 1.0, borderType=cv2.BORDER_REFLECT_101)
    wide = cv2.GaussianBlur(frame, (0, 0), 3.0, borderType=cv2.BORDER_REFLECT_101)
    out = blur_difference(frame.copy(), 1.0, w, 3.0)
    np.testing.assert_allclose(out, sharp + w * (wide - sharp), atol=1e-4)
    np.testing.assert_array_equal(blur_difference(frame.copy(), 1.0, None, 3.0), sharp)
    np.testing.assert_array_equal(blur_difference(frame.copy(), 1.0, w, 0.0), sharp)


def test_large_dots_under_jpeg_get_their_own_blur_and_it_pays(folders, tmp_path,
                                                              monkeypatch) -> None:
    """Dots of 20 px through JPEG (quality 70, colour at half resolution): the calibration
    blurs the difference on the dots by DOT_BLUR_MM (2.5 px at 0.06 mm/px), stores it, and its
    held-out depth error is below that of the same calibration without it."""
    import cv2

    from vtsbench.depth import markers

    plain, _, _ = folders
    big = tmp_path / "big"
    shutil.copytree(plain, big)
    m = load_manifest(big)
    img = read_image(big / m.entries[0].source.path)
    layer = dot_layer(*img.shape[:2], MM_PER_PX, pitch=2.4, diameter=1.2, darkness=0.75)
    files = {e.source.path for e in m.entries} | {s.background for s in m.sessions
                                                  if s.background}
    for f in files:
        im = np.clip(np.rint(read_image(big / f) * layer[..., None]), 0, 255).astype(np.uint8)
        ok, buf = cv2.imencode(".jpg", im[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, 70])
        assert ok
        write_png(big / f, np.ascontiguousarray(cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1]))

    def held(seeds=(0, 1, 2)) -> tuple[float, float]:
        runs = [calibrate(big, method="poly", holdout=2, seed=s, device=None) for s in seeds]
        spec = runs[0].calibration.markers
        assert spec is not None and 17 <= spec.diameter_px <= 23
        return float(np.mean([held_rmse(r) for r in runs])), spec.dot_blur_px

    with_blur, px = held()
    assert px == pytest.approx(markers.DOT_BLUR_MM / MM_PER_PX)
    monkeypatch.setattr(markers, "DOT_BLUR_MM", 0.0)
    without, px0 = held()
    assert px0 == 0.0
    assert with_blur < 0.97 * without


@pytest.mark.parametrize("dot_mm, pitch_mm, dark", [(0.5, 1.6, 0.5), (0.35, 1.0, 0.6),
                                                    (1.33, 2.72, 0.82), (1.6, 2.4, 0.9)])
def test_other_prints_are_found_at_their_size(dot_mm, pitch_mm, dark) -> None:
    """The simulator's marker gel printed otherwise (small and faint, tiny and dense, dark,
    large and dense: `circles_sim_variants.py --dots`): the grid is
    found in the background through its camera and JPEG, its dots about their printed size,
    nearly every dot of the frame counted."""
    import dataclasses

    from vtsbench.sim.appearance import background, sensor_appearance
    from vtsbench.sim.optics import Capture, sensor

    mm, shape = 0.05, (240, 320)
    app = dataclasses.replace(sensor_appearance("markers"), marker_diameter_mm=dot_mm,
                              marker_pitch_mm=pitch_mm, marker_darkness=dark)
    bg = background(app, sensor(*shape, mm, lights="zones3"), Capture(gel=0),
                    np.random.default_rng([0, 1]))
    spec = detect_markers(bg, mm)
    assert spec is not None
    assert spec.diameter_px == pytest.approx(dot_mm / mm, rel=0.25)
    whole = (shape[0] * mm // pitch_mm) * (shape[1] * mm // pitch_mm)  # dots wholly inside
    assert spec.n_dots >= 0.8 * whole
