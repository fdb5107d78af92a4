"""Centres that agree with the sensor's colour response (vtsbench.depth.centres)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from vtsbench.depth.centres import consistent_centres, sphere_centre
from vtsbench.depth.sphere import sphere_fields


@pytest.mark.parametrize("x, y, r", [(60.3, 50.7, 14.0), (20.25, 40.5, 18.0), (3.0, 47.6, 15.0)])
def test_sphere_centre_finds_a_sub_pixel_apex_from_a_start_off_by_pixels(x, y, r) -> None:
    # the ball's own slopes, also cut by the image border (x = 3) and near its equator
    f = sphere_fields((96, 128), x, y, r, 1.0, (0.06, 0.06))
    g = np.stack([f.p, f.q], axis=-1)
    cx, cy = sphere_centre(g, x + 2.5, y - 2.0, r, 1.0, (0.06, 0.06))
    assert math.hypot(cx - x, cy - y) < 0.05


def test_sphere_centre_with_noise_saturation_and_an_anisotropic_scale() -> None:
    scale = (0.05, 0.06)
    f = sphere_fields((96, 128), 64.4, 40.2, 16.0, 1.5, scale)
    g = np.stack([f.p, f.q], axis=-1) + np.random.default_rng(0).normal(0, 0.05, (96, 128, 2))
    g[38:43, 60:70] = 5.0  # a saturated patch: wrong slopes inside the contact
    cx, cy = sphere_centre(g.astype(np.float32), 62.0, 42.0, 16.0, 1.5, scale)
    assert math.hypot(cx - 64.4, cy - 40.2) < 1.0  # a tenth of the disc wrong by 5 mm/mm


def test_sphere_centre_keeps_the_start_without_contact_or_pixels() -> None:
    flat = np.zeros((48, 64, 2), np.float32)
    cx, cy = sphere_centre(flat, 30.0, 20.0, 10.0, 1.0, (0.06, 0.06))
    assert math.hypot(cx - 30, cy - 20) < 1.0  # no slopes: nothing pulls the centre far
    assert sphere_centre(flat, -50.0, -50.0, 2.0, 1.0, (0.06, 0.06)) == (-50.0, -50.0)


def test_consistent_centres_bring_moved_labels_back(tmp_path) -> None:
    from vtsbench.depth.calibration import load_presses
    from vtsbench.sim.simulate import simulate

    root = tmp_path / "sim"
    simulate(root, seed=11, n_static=0, n_sequences=0, n_presses=40, size=(120, 160),
             mm_per_px=0.06)
    presses, bg, setup, _ = load_presses(root)
    truth = np.array([(p.x, p.y) for p in presses])
    moves = {1: (3.5, -1.0), 4: (-2.5, 2.5), 7: (0.5, 3.5), 13: (3.0, 2.0), 22: (-3.0, -2.0)}
    start = [replace(p, x=p.x + moves.get(i, (0, 0))[0], y=p.y + moves.get(i, (0, 0))[1])
             for i, p in enumerate(presses)]
    got = np.array(consistent_centres(start, bg, setup, rounds=2))
    err = np.hypot(*(got - truth).T)
    assert err[list(moves)].max() < 1.2, err  # 3.5-3.6 px off before
    assert err.max() < 1.2, err  # the others stay put
    with pytest.raises(ValueError, match="at least 30 presses"):
        consistent_centres(start[:10], bg, setup)


def test_symmetric_centre_on_a_disc_wider_than_opencv_maps_one_row() -> None:
    """A disc of 150 px holds 70,000 pixels, beyond the 32,767 OpenCV's remap takes along a
    side; the search still finds the centre of a point-symmetric ring from 5 px off."""
    from vtsbench.depth.centres import symmetric_centre

    h, w, cx, cy = 600, 700, 340.25, 290.5
    yy, xx = np.mgrid[:h, :w].astype(np.float32)
    rho = np.hypot(xx - cx, yy - cy)
    m = (np.exp(-((rho - 100) / 8) ** 2) + 0.3 * np.exp(-(rho / 40) ** 2)).astype(np.float32)
    m += 0.5 * np.exp(-((xx - cx - 70) ** 2 + (yy - cy) ** 2) / 200)  # a lobe, and its twin
    m += 0.5 * np.exp(-((xx - cx + 70) ** 2 + (yy - cy) ** 2) / 200)
    sx, sy = symmetric_centre(m, cx + 4.0, cy - 3.0, 150.0)
    assert math.hypot(sx - cx, sy - cy) <= 0.3
