"""Circles on presses whose background was taken under another light (a drift and a texture
left between them), and on small imprints: rendered presses with their known circle, and DIGIT
press 0016 of the real set when it is present (as recorded and rescaled by 2)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from tests.fixtures.data import real_dir
from vtsbench.depth.imprint import ring_contrast
from vtsbench.depth.sphere import RING_Z_MIN, change_map, circle_doubts, detect_circle

LIGHTS = [((255, 40, 40), 90, 25), ((40, 255, 40), 210, 25), ((40, 40, 255), 330, 25)]


def render(h: int, w: int, x: float, y: float, r: float, ball: float, *, press: bool = True,
           seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(background, press) RGB float64: a ball of `ball` px pressed to a contact of radius r at
    (x, y) under three coloured side lights, rendered at twice the size and averaged down."""
    ss = 2
    yy, xx = np.mgrid[:h * ss, :w * ss].astype(np.float64)
    xx, yy = (xx + 0.5) / ss - 0.5, (yy + 0.5) / ss - 0.5
    rho = np.hypot(xx - x, yy - y)
    rim = math.sqrt(ball**2 - r**2)
    z = np.where(rho < r, np.sqrt(np.maximum(ball**2 - np.minimum(rho, r) ** 2, 0)) - rim,
                 -0.03 * r * (r / rim) * (1 - np.exp(-(rho - r) / (0.1 * r))))
    z = z if press else np.zeros_like(z)
    gy, gx = np.gradient(z)
    nrm = np.stack([gx * ss, gy * ss, np.ones_like(z)], -1)
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    img, bg = np.zeros((h * ss, w * ss, 3)), np.zeros((h * ss, w * ss, 3))
    for colour, az, el in LIGHTS:
        a, e = math.radians(az), math.radians(el)
        light = np.array([math.cos(a) * math.cos(e), math.sin(a) * math.cos(e), math.sin(e)])
        fall = 0.75 + 0.5 * ((xx / w - 0.5) * math.cos(a) + (yy / h - 0.5) * math.sin(a))
        col = np.array(colour, np.float64)
        img += col * (fall * np.clip(nrm @ light, 0, None))[..., None]
        bg += col * (fall * math.sin(e))[..., None]
    img = img.reshape(h, ss, w, ss, 3).mean(axis=(1, 3))
    bg = bg.reshape(h, ss, w, ss, 3).mean(axis=(1, 3))
    scale = 200 / bg.max()
    rng = np.random.default_rng(seed)
    return bg * scale + rng.normal(0, 1, bg.shape), img * scale + rng.normal(0, 1, bg.shape)


def other_light(h: int, w: int, dn: float, seed: int) -> np.ndarray:
    """What another light leaves between a press and its background: a texture of blobs about
    6 px wide of `dn` DN robust deviation per channel, on a smooth drift of up to 60 DN."""
    rng = np.random.default_rng(100 + seed)
    t = np.stack([cv2.GaussianBlur(rng.normal(0, 1, (h, w)).astype(np.float32), (0, 0), 6)
                  for _ in range(3)], -1)
    t /= np.median(np.abs(t)) * 1.4826
    yy, xx = np.mgrid[:h, :w] / max(h, w)
    drift = 60 * ((xx - 0.3) ** 2)[..., None] * np.array([1, -0.6, 0.4]) \
        + 30 * yy[..., None] * np.array([-0.5, 1, 0.2])
    return dn * t + drift


def u8(a: np.ndarray) -> np.ndarray:
    return np.clip(a, 0, 255).round().astype(np.uint8)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_press_under_another_light_is_found_and_its_texture_alone_is_not(seed) -> None:
    """The imprint's change is strong on one side and weak on the other (a crescent, as under
    side lights), on a texture of 13 DN robust deviation and a 60 DN drift: the contact is
    found within 1.5 px and 5 %, its rim stands above the texture, and the texture without a
    press gives no circle."""
    h, w, ball, (x, y, r) = 320, 240, 63.3, (131.3, 148.6, 26.0)
    bg, img = render(h, w, x, y, r, ball, seed=seed)
    yy, xx = np.mgrid[:h, :w]
    gain = 0.5 + 0.5 * np.clip(np.cos(np.arctan2(yy - y, xx - x) + 0.8), 0, None)
    tex = other_light(h, w, 13.0, seed)
    press, still, bg = u8(bg + (img - bg) * gain[..., None] + tex), u8(bg + tex), u8(bg)
    found = detect_circle(press, bg, ball_px=ball)
    assert found is not None
    assert math.hypot(found[0] - x, found[1] - y) < 1.5 and abs(found[2] / r - 1) < 0.05, found
    assert ring_contrast(change_map(press, bg, 1.0, markers=True), found) >= RING_Z_MIN
    assert detect_circle(still, bg, ball_px=ball) is None
    m = change_map(still, bg, 1.0, markers=True)
    assert ring_contrast(m, (x, y, r)) < RING_Z_MIN  # the same circle on the texture alone


@pytest.mark.parametrize("r", [12.0, 14.5, 17.0])
def test_a_small_imprint_keeps_its_radius(r) -> None:
    """A contact of 12-17 px (a 31.6 px ball, DIGIT's presses at half size), rendered at twice
    the size and averaged down: the radius within 5 % and the centre within 1 px."""
    x, y = 58.3, 83.6
    bg, img = render(320, 240, 2 * x + 0.5, 2 * y + 0.5, 2 * r, 63.2)
    bg, img = (cv2.resize(u8(a), (120, 160), interpolation=cv2.INTER_AREA) for a in (bg, img))
    found = detect_circle(img, bg, ball_px=31.6)
    assert found is not None
    assert math.hypot(found[0] - x, found[1] - y) < 1.0 and abs(found[2] / r - 1) < 0.05, found


def test_no_contact_under_the_press_light_gives_none() -> None:
    """Frames without contact, with and without another light's texture, give no circle."""
    bg, img = render(320, 240, 120, 160, 26.0, 63.3, press=False, seed=4)
    assert detect_circle(u8(img), u8(bg), ball_px=63.3) is None
    for dn in (6.0, 13.0, 17.0):
        tex = other_light(320, 240, dn, 7)
        assert detect_circle(u8(img + tex), u8(bg), ball_px=63.3) is None, dn


@pytest.mark.parametrize("scale", [1, 2])
@pytest.mark.parametrize("order", ["bgr", "rgb"])
def test_digit_press_0016_under_another_light_is_found(scale, order) -> None:
    """DIGIT press 0016 (taken under another light than the presses whose median is its
    background) shows a contact: it is found, its circle passes the calibration's check, and
    it lies on the imprint (centre within 3 px of (148, 129.5), read off an overlay), in either
    channel order and rescaled by 2 (there the disc search at the usual level fits a circle to
    the texture, whose rim does not stand out of it: the texture level is searched then too)."""
    folder = real_dir("digit_ball_6mm")
    frames = {p.stem: cv2.imread(str(p)) for p in sorted(folder.glob("*.png"))}
    if "0016" not in frames:
        pytest.skip("press 0016 not present")
    if scale != 1:
        frames = {k: cv2.resize(a, None, fx=scale, fy=scale, interpolation=cv2.INTER_CUBIC)
                  for k, a in frames.items()}
    if order == "rgb":
        frames = {k: np.ascontiguousarray(a[..., ::-1]) for k, a in frames.items()}
    bg = np.median(np.stack(list(frames.values())), axis=0).round().astype(np.uint8)
    ball = 3.0 * 21.09 * scale
    found = detect_circle(frames["0016"], bg, ball_px=ball)
    assert found is not None
    assert circle_doubts(found, frames["0016"], bg, ball) == []
    cx, cy = (148.0 + 0.5) * scale - 0.5, (129.5 + 0.5) * scale - 0.5
    assert math.hypot(found[0] - cx, found[1] - cy) < 3 * scale, found
    assert 22 * scale < found[2] < 32 * scale, found
