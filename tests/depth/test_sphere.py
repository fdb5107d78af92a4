"""The sphere model of a ball press, its rim handling, and finding the contact circle."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.fixtures.calibration import sim_folder
from vtsbench.depth.sphere import (
    Rim,
    _best_of_starts,
    ball_radius_px,
    cap_depth_mm,
    change_map,
    clamp_radius,
    detect_circle,
    edge_support,
    fit_circle,
    imprint_lobes,
    ransac_circle,
    refine_circle,
    sphere_fields,
)
from vtsbench.recordings.manifest import load_manifest
from vtsbench.recordings.media import read_image

MM = 0.05  # mm per px
R_MM = 2.0  # ball radius: 40 px


@pytest.fixture(scope="module")
def sim(tmp_path_factory: pytest.TempPathFactory):
    return sim_folder(tmp_path_factory)


def test_gradients_and_depth_follow_the_sphere() -> None:
    x, y, r = 60.3, 50.7, 25.0
    f = sphere_fields((100, 120), x, y, r, R_MM, MM)
    big_r = R_MM / MM
    yy, xx = np.mgrid[0:100, 0:120]
    rho = np.hypot(xx - x, yy - y)
    inside = rho < r
    root = np.sqrt(big_r**2 - rho[inside] ** 2)
    np.testing.assert_allclose(f.p[inside], -(xx - x)[inside] / root, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(f.q[inside], -(yy - y)[inside] / root, rtol=1e-5, atol=1e-6)
    want = (root - math.sqrt(big_r**2 - r**2)) * MM
    np.testing.assert_allclose(f.depth_mm[inside], want, rtol=1e-5, atol=1e-6)
    assert (f.p[~inside] == 0).all() and (f.depth_mm[~inside] == 0).all()
    assert f.depth_mm.max() == pytest.approx(cap_depth_mm(r, R_MM, MM), rel=1e-3)
    # The gradients are those of the depth (central differences, away from the rim).
    gy, gx = np.gradient(f.depth_mm.astype(np.float64), MM)
    core = rho < r - 2
    np.testing.assert_allclose(gx[core], f.p[core], atol=2e-3)
    np.testing.assert_allclose(gy[core], f.q[core], atol=2e-3)


@pytest.mark.parametrize("r", [1.0, 3.0, 20.0, 37.0, 39.5, 40.0, 44.0])
def test_rim_is_finite_from_barely_touching_to_the_equator(r: float) -> None:
    """Presses from a touch to (and past) the ball's radius give finite values everywhere."""
    f = sphere_fields((90, 90), 45.0, 45.0, r, R_MM, MM)
    for a in (f.p, f.q, f.depth_mm):
        assert np.isfinite(a).all()
    rim = Rim()
    assert f.r_px == pytest.approx(min(r, rim.max_radius_frac * 40.0))
    slope = np.hypot(f.p, f.q)
    assert slope[f.trusted].max(initial=0) <= rim.max_slope + 1e-6
    assert slope.max() < 10  # the clamped rim bounds the slope (0.97 R: 3.99)
    # Trusted labels stay clear of the rim; flat samples clear of the contact.
    yy, xx = np.mgrid[0:90, 0:90]
    rho = np.hypot(xx - 45.0, yy - 45.0)
    if f.trusted.any():
        assert rho[f.trusted].max() <= f.r_px - rim.shrink(f.r_px) + 1e-9
    if f.flat.any():
        assert rho[f.flat].min() >= f.r_px + max(f.r_px, rim.flat_margin_mm / MM) - 1e-9
    assert not (f.trusted & f.flat).any()


def test_rim_settings_shrink_and_cap() -> None:
    rim = Rim(shrink_px=2.0, shrink_frac=0.1, max_slope=1.0)
    f = sphere_fields((100, 100), 50.0, 50.0, 36.0, R_MM, MM, rim)
    yy, xx = np.mgrid[0:100, 0:100]
    rho = np.hypot(xx - 50.0, yy - 50.0)
    # Slope 1 at rho = R / sqrt(2) = 28.3 px, below 36 - 3.6: the slope cap decides.
    assert rho[f.trusted].max() <= 40 / math.sqrt(2) + 1e-6
    assert rim.shrink(10) == 2.0 and rim.shrink(50) == 5.0
    assert Rim.from_dict(rim.to_dict()) == rim


def test_radius_clamp_and_scale() -> None:
    assert ball_radius_px(3.0, 0.03) == pytest.approx(100.0)
    assert ball_radius_px(3.0, (0.03, 0.03)) == pytest.approx(100.0)
    assert clamp_radius(120.0, 3.0, 0.03) == pytest.approx(97.0)
    assert clamp_radius(50.0, 3.0, 0.03) == 50.0
    f = sphere_fields((60, 80), 40.0, 30.0, 15.0, 1.0, (0.04, 0.05))  # anisotropic
    assert np.isfinite(f.p).all() and f.contact.any()


def test_fit_circle_exact() -> None:
    t = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    cx, cy, r = fit_circle(12.5 + 7 * np.cos(t), -3 + 7 * np.sin(t))
    assert (cx, cy, r) == pytest.approx((12.5, -3, 7), abs=1e-9)


def test_ransac_circle_ignores_outliers_and_respects_the_radius_prior() -> None:
    rng = np.random.default_rng(3)
    t = rng.uniform(0, 2 * np.pi, 120)
    xs, ys = 40.3 + 12.6 * np.cos(t), 31.7 + 12.6 * np.sin(t)
    xs[:40] = rng.uniform(20, 60, 40)  # a third of the points are outliers
    ys[:40] = rng.uniform(10, 50, 40)
    (cx, cy, r), inl = ransac_circle(xs, ys, np.ones(120), r_range=(3, 30), tol=0.5)
    assert (cx, cy, r) == pytest.approx((40.3, 31.7, 12.6), abs=0.02)  # outliers within tol
    assert inl[40:].all() and inl[:40].sum() < 8
    # the prior: a radius range that excludes the circle never returns it
    other = ransac_circle(xs, ys, np.ones(120), r_range=(20, 30), tol=0.5)
    assert other is None or 19.5 <= other[0][2] <= 30.5
    assert ransac_circle(xs[40:], ys[40:], np.ones(80), r_range=(20, 30), tol=0.5) is None
    assert ransac_circle(xs[:2], ys[:2], np.ones(2), r_range=(3, 30), tol=0.5) is None


def test_geometric_refinement_removes_the_algebraic_bias_on_an_arc() -> None:
    """A contact cut by the image border leaves a quarter of its outline: with noise the
    algebraic fit shrinks the circle (by 1 px here, on average), the geometric one does not."""
    rng = np.random.default_rng(0)
    alg, geo = [], []
    for _ in range(100):
        t = np.linspace(0, np.pi / 2, 60)
        xs = 10 + 20 * np.cos(t) + rng.normal(0, 0.5, 60)
        ys = -4 + 20 * np.sin(t) + rng.normal(0, 0.5, 60)
        a = fit_circle(xs, ys)
        alg.append(a[2] - 20)
        geo.append(refine_circle(xs, ys, np.ones(60), a)[2] - 20)
    assert np.mean(alg) < -0.7
    assert abs(np.mean(geo)) < 0.15


def _rendered_press(x: float, y: float, r: float, h: int = 96, w: int = 128,
                    ss: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """A background and a press whose colour change rises towards the rim (like the slope of
    a cap) and stops at the circle (x, y, r), anti-aliased by ss x ss supersampling; the
    light comes from one side, so the change is lopsided."""
    yy, xx = np.mgrid[:h * ss, :w * ss]
    xx = (xx + 0.5) / ss - 0.5
    yy = (yy + 0.5) / ss - 0.5
    rho = np.hypot(xx - x, yy - y)
    side = 0.6 + 0.4 * np.cos(np.arctan2(yy - y, xx - x) - 0.7)
    change = np.where(rho < r, 20 + 60 * (rho / r) ** 2, 0.0) * side
    change = change.reshape(h, ss, w, ss).mean(axis=(1, 3))
    bg = np.full((h, w, 3), 110.0)
    img = bg.copy()
    img[..., 0] += change
    img[..., 1] -= 0.5 * change
    img[..., 2] += 0.3 * change
    rng = np.random.default_rng(1)
    img += rng.normal(0, 1.0, img.shape)
    return bg.astype(np.uint8), np.clip(img, 0, 255).round().astype(np.uint8)


@pytest.mark.parametrize("x, y, r", [(60.37, 50.81, 14.6), (41.5, 44.25, 23.3),
                                     (120.2, 48.6, 18.4)])  # the last one cut by the border
def test_detect_circle_is_sub_pixel_on_a_known_circle(x, y, r) -> None:
    bg, img = _rendered_press(x, y, r)
    cx, cy, cr = detect_circle(img, bg, ball_px=1.2 * r)
    assert math.hypot(cx - x, cy - y) < 0.35, (cx, cy, cr)
    assert abs(cr - r) < 0.5, (cx, cy, cr)


def test_detect_circle_ignores_a_change_beside_the_contact() -> None:
    """A bright patch touching the imprint (a fold, a speck of dirt) does not move the circle."""
    bg, img = _rendered_press(60.37, 50.81, 14.6)
    img = img.copy()
    img[30:40, 76:84, 0] = 250  # beside the rim, up and right
    cx, cy, cr = detect_circle(img, bg, ball_px=18)
    assert math.hypot(cx - 60.37, cy - 50.81) < 0.5 and abs(cr - 14.6) < 0.6


def _banded_press(x: float, y: float, r: float, h: int = 96, w: int = 128, ss: int = 8
                  ) -> tuple[np.ndarray, np.ndarray]:
    """A press lit along the rows only: the change follows the slope down the rows, so it is
    zero along the row through the apex and comes in two lobes (one dimmer) with a dark band
    between them, brightest inside the rim and fading over a skirt outside it."""
    yy, xx = np.mgrid[:h * ss, :w * ss]
    xx = (xx + 0.5) / ss - 0.5
    yy = (yy + 0.5) / ss - 0.5
    rho = np.hypot(xx - x, yy - y)
    sin = (yy - y) / np.maximum(rho, 1e-9)
    lobe = np.where(rho < r, np.exp(-(((rho - 0.7 * r) / (0.35 * r)) ** 2)),
                    math.exp(-((0.3 / 0.35) ** 2)) * np.exp(-(rho - r) / (0.25 * r)))
    change = 110 * np.sign(sin) * np.abs(sin) ** 1.5 * lobe * np.where(sin < 0, 1.0, 0.6)
    change = change.reshape(h, ss, w, ss).mean(axis=(1, 3))
    bg = np.full((h, w, 3), 110.0)
    img = bg.copy()
    img[..., 0] += change
    img[..., 2] -= 0.8 * change
    img += np.random.default_rng(1).normal(0, 1.0, img.shape)
    return bg.astype(np.uint8), np.clip(img, 0, 255).round().astype(np.uint8)


@pytest.mark.parametrize("x, y, r", [(60.37, 50.81, 14.6), (41.5, 44.25, 23.3),
                                     (70.2, 48.6, 18.4)])
def test_detect_circle_joins_the_two_halves_of_a_banded_imprint(x, y, r) -> None:
    """A dark band through the apex splits the strong change in two: the circle is found from
    both halves, not around the larger one (which alone gave circles of a quarter of the radius
    10-15 px off the centre)."""
    bg, img = _banded_press(x, y, r)
    m = change_map(img, bg, 1.0)
    lobes = imprint_lobes(m, 3.0)
    assert lobes is not None
    ys = np.nonzero(lobes)[0]
    assert ys.min() < y - 0.3 * r and ys.max() > y + 0.3 * r  # both halves
    for restarts in (True, False):
        cx, cy, cr = detect_circle(img, bg, ball_px=1.6 * r, restarts=restarts)
        assert math.hypot(cx - x, cy - y) < 0.5 and 0.8 * r < cr < 1.1 * r, (cx, cy, cr)
    # a change of the same size far off is not joined: the circle stays on the imprint
    far = img.copy()
    patch = far[4:14, 110:122].astype(int) + np.array([90, 0, -70])
    far[4:14, 110:122] = np.clip(patch, 0, 255)
    cx, cy, _ = detect_circle(far, bg, ball_px=1.6 * r)
    assert math.hypot(cx - x, cy - y) < 0.5


def test_edge_support_prefers_the_circle_on_the_rim() -> None:
    bg, img = _rendered_press(60.37, 50.81, 14.6)
    m = change_map(img, bg, 1.0)
    true = edge_support(m, (60.37, 50.81, 14.6), 1.0)
    assert true > 1.5 * edge_support(m, (63.0, 49.0, 14.6), 1.0)  # centre 3.2 px off
    assert true > 1.5 * edge_support(m, (60.37, 50.81, 11.0), 1.0)  # inside the rim
    assert edge_support(change_map(bg, bg, 1.0), (60.0, 50.0, 14.0), 1.0) == 0.0


@pytest.mark.parametrize("x, y, r", [(60.37, 50.81, 14.6), (120.2, 48.6, 18.4)])
def test_restarts_leave_the_rim_for_nothing_less(x, y, r) -> None:
    """A circle off the ring is replaced by the restart that finds the ring (also cut by the
    border); the circle on the ring stays (no restart gains a fifth of its support)."""
    bg, img = _rendered_press(x, y, r)
    m = change_map(img, bg, 1.0)
    cx, cy, cr = _best_of_starts(m, (x - 2.5, y + 2.0, r - 2.0), 1.0, 3.0, 1.2 * r)
    assert math.hypot(cx - x, cy - y) < 0.35 and abs(cr - r) < 0.5, (cx, cy, cr)
    on = detect_circle(img, bg, ball_px=1.2 * r, restarts=False)
    assert _best_of_starts(m, on, 1.0, 3.0, 1.2 * r) == on
    assert detect_circle(img, bg, ball_px=1.2 * r) == on
    assert _best_of_starts(m, None, 1.0, 3.0, 1.2 * r) is None


def test_detect_circle_recovers_labelled_circles(sim) -> None:
    """On the simulated presses the detected circle is within 1.5 px of the label."""
    m = load_manifest(sim)
    bgs = {s.id: read_image(sim / s.background) for s in m.sessions}
    for e in m.entries:
        found = detect_circle(read_image(sim / e.source.path), bgs[e.session])
        assert found is not None, e.id
        x, y, r = found
        assert math.hypot(x - e.circle.x, y - e.circle.y) < 1.5, (e.id, found, e.circle)
        assert abs(r - e.circle.r) < 1.5, (e.id, found, e.circle)


def test_detect_circle_finds_nothing_without_contact(sim) -> None:
    m = load_manifest(sim)
    bg = read_image(sim / m.sessions[0].background)
    other = read_image(sim / m.sessions[1].background)  # same gel, another noise draw
    assert detect_circle(other, bg) is None
    assert detect_circle(bg, bg) is None
    flat = np.full_like(bg, 128)
    assert detect_circle(flat, flat) is None
