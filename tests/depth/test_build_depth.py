"""The build's depth and contact path: the same depth as `reconstruct`, bit for bit, and the
OpenCV mask cleaning against scipy.ndimage's binary morphology."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy import ndimage

from vtsbench.depth.depthmaps import CONTACT_PARAMS, DepthMaker
from vtsbench.depth.mask import clean_mask, disc


def scipy_clean_mask(raw: np.ndarray, close_px: int, min_area_px: int,
                     dilate_px: int) -> np.ndarray:
    """clean_mask written with scipy.ndimage (what it computed before it ran on OpenCV)."""
    out = np.empty_like(raw)
    pad = max(close_px, 0) + 1
    four = ndimage.generate_binary_structure(2, 1)
    for k, m in enumerate(raw.reshape(-1, *raw.shape[-2:])):
        if close_px > 0:
            m = ndimage.binary_closing(np.pad(m, pad), structure=disc(close_px))[pad:-pad,
                                                                                 pad:-pad]
        m = ndimage.binary_fill_holes(m)
        if min_area_px > 1 and m.any():
            labels, n = ndimage.label(m, structure=four)
            keep = np.bincount(labels.ravel(), minlength=n + 1) >= min_area_px
            keep[0] = False
            m = keep[labels]
        if dilate_px > 0 and m.any():
            m = ndimage.binary_dilation(m, structure=disc(dilate_px))
        out.reshape(-1, *raw.shape[-2:])[k] = m
    return out


def test_clean_mask_matches_scipy_morphology() -> None:
    rng = np.random.default_rng(7)
    for trial in range(60):
        h, w = (int(v) for v in rng.integers(1, 48, 2))
        if trial % 2:
            raw = rng.random((h, w)) < rng.uniform(0.05, 0.8)
        else:  # blobs with holes and specks
            noise = ndimage.gaussian_filter(rng.random((h, w)), 2)
            raw = noise > np.quantile(noise, rng.uniform(0.3, 0.9))
        for close_px, min_area_px, dilate_px in ((3, 20, 2), (0, 0, 0), (1, 2, 1), (2, 5, 0),
                                                 (5, 1, 4)):
            got = clean_mask(raw, close_px=close_px, min_area_px=min_area_px,
                             dilate_px=dilate_px)
            want = scipy_clean_mask(raw, close_px, min_area_px, dilate_px)
            assert got.dtype == bool and np.array_equal(got, want), (trial, close_px)
    batch = rng.random((2, 3, 20, 30)) < 0.3
    assert np.array_equal(clean_mask(batch), scipy_clean_mask(batch, 3, 20, 2))


def test_clean_mask_of_a_box_equals_the_frame() -> None:
    """clean_mask cleans the raw pixels' bounding box grown by its reach: contacts in the middle,
    touching each border and each corner, with rings (holes) and specks, as scipy.ndimage
    cleans the whole frame."""
    rng = np.random.default_rng(3)
    h, w = 90, 120
    yy, xx = np.mgrid[:h, :w]
    for cy, cx in ((45, 60), (0, 60), (89, 60), (45, 0), (45, 119), (0, 0), (89, 119), (3, 115)):
        r = np.hypot(yy - cy, xx - cx)
        raw = (r < 9) & ~((r > 4) & (r < 5.5))  # a disc with a ring-shaped gap
        raw |= (r > 12) & (r < 14) & (rng.random((h, w)) < 0.8)  # a broken ring around it
        raw |= rng.random((h, w)) < 0.002  # specks anywhere
        for close_px, min_area_px, dilate_px in ((3, 20, 2), (0, 0, 0), (5, 1, 4)):
            got = clean_mask(raw, close_px=close_px, min_area_px=min_area_px,
                             dilate_px=dilate_px)
            want = scipy_clean_mask(raw, close_px, min_area_px, dilate_px)
            assert np.array_equal(got, want), (cy, cx, close_px)
    assert not clean_mask(np.zeros((2, h, w), bool)).any()


def test_depth_maker_equals_reconstruct(sim_recordings: Path) -> None:
    from vtsbench.depth.calibration import load_calibration
    from vtsbench.depth.reconstruct import reconstruct
    from vtsbench.recordings.media import read_frames

    cal = load_calibration(sim_recordings / "calibration.safetensors")
    frames = read_frames(sim_recordings / "sequences" / "seq-00002", 0, 8)
    mk = DepthMaker(cal)
    assert mk.lut is not None and mk.still_is_zero and mk.zero_folded
    for solver in ("dct", "dst"):
        want = reconstruct(frames, cal, solver=solver)
        got = np.stack([mk.depth(f, solver) for f in frames])
        assert got.dtype == np.float32 and np.array_equal(got, want), solver
    diff = mk.difference(frames[-1]).copy()
    contact = mk.contact(diff)
    assert np.array_equal(mk.gradients(diff), cal.gradients(frames[-1:])[0])
    want = reconstruct(frames[-1], cal, solver="masked", mask=contact)
    assert np.array_equal(mk.integrate(mk.gradients(diff), "masked", contact), want)
    # the contact: colour distance above the threshold, cleaned
    raw = np.sqrt((diff.astype(np.float64) ** 2).sum(-1)) > CONTACT_PARAMS["threshold"] * 255
    assert contact.any() and np.array_equal(
        contact, scipy_clean_mask(raw, CONTACT_PARAMS["close_px"],
                                  CONTACT_PARAMS["min_area_px"], CONTACT_PARAMS["dilate_px"]))
    # a mapping other than the lut goes through its own predict, with the same result
    mk.lut = None
    assert np.array_equal(mk.depth(frames[3]), reconstruct(frames[3], cal))


def test_channel_sum_is_numpys_float32_sum() -> None:
    """contact sums the squared channels with cv2.transform: the same float32 values as numpy's
    (r + g) + b, including magnitudes far apart, zeros and the colour limit's squares."""
    import cv2

    from vtsbench.depth.depthmaps import _ONES

    rng = np.random.default_rng(0)
    scale = 10.0 ** rng.integers(-6, 5, (256, 320, 3))
    sq = (rng.random((256, 320, 3)) * scale).astype(np.float32)
    sq[::7, :, 1] = 0.0
    sq[::5, ::3] = np.float32(118.86745) ** 2
    want = (sq[..., 0] + sq[..., 1]) + sq[..., 2]
    assert want.dtype == np.float32
    assert np.array_equal(cv2.transform(sq, _ONES), want)
