"""The simulator's light layouts: the default keeps every byte, each preset does what it says
(four sides light the press from four sides, near-uniform light shades it weakly), and a ball
press is found under each, with and without a marker gel."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from vtsbench.depth.sphere import detect_circle
from vtsbench.sim.appearance import background, sensor_appearance
from vtsbench.sim.objects import BALL, random_instance
from vtsbench.sim.optics import LIGHTS, Capture, sensor
from vtsbench.sim.plan import press_scene
from vtsbench.sim.relight import relight
from vtsbench.sim.scene import Effects, Rendered, Scene, render

SIZE, MPP = (120, 160), 0.1


def _press(size: tuple[int, int] = SIZE, centre: tuple[float, float] = (83.3, 57.6),
           depth: float = 0.6, mm_per_px: float = MPP) -> tuple[Scene, Rendered]:
    """A ball pressed depth mm deep at centre (px), and its exact truth (no noise)."""
    obj = random_instance(BALL, np.random.default_rng(0))
    scene = Scene(obj, (centre,), (depth,), size, mm_per_px,
                  Effects(texture=False, noise=False))
    return scene, render(scene)


def test_sensor_default_is_the_three_zones_byte_for_byte() -> None:
    old = sensor(*SIZE, MPP)
    named = sensor(*SIZE, MPP, lights="zones3")
    assert old.lights == "zones3" and old.light.shape[0] == 3
    for f in ("light", "gain", "ambient", "flat", "mix"):
        assert np.array_equal(getattr(old, f), getattr(named, f)), f
    with pytest.raises(ValueError, match="lights must be one of"):
        sensor(*SIZE, MPP, lights="spotlight")


@pytest.mark.parametrize("generator", [1, 2])
def test_relight_through_the_default_layout_is_render(generator) -> None:
    """The same scene and noise draws: relight of the truth gives render's frames exactly."""
    app = sensor_appearance("markers") if generator == 2 else None
    scene = press_scene(np.random.default_rng(3), SIZE, MPP, generator, app)
    shot = render(scene, Capture(gel=1), np.random.default_rng(9))
    truth = render(scene.with_effects(dataclasses.replace(scene.effects, noise=False)))
    again = relight(truth.grad, sensor(*SIZE, MPP), Capture(gel=1), np.random.default_rng(9),
                    scene.appearance)
    assert np.array_equal(again, shot.frames)


def _deviation(lights: str, rendered: Rendered) -> np.ndarray:
    """(H, W, 3) float: the noise-free press minus the flat image under a layout."""
    s = sensor(*SIZE, MPP, lights=lights)
    return relight(rendered.grad, s)[0].astype(float) - relight(rendered.grad * 0, s)[0]


def test_every_layout_reads_the_flat_level_at_the_centre() -> None:
    for name in LIGHTS:
        s = sensor(*SIZE, MPP, lights=name)
        np.testing.assert_allclose(s.flat[SIZE[0] // 2, SIZE[1] // 2], [156, 150, 160],
                                   atol=0.01, err_msg=name)


def test_uniform_light_shades_weakly() -> None:
    """Near-uniform light changes a press's colour far less than side lights, and in grey."""
    _, r = _press()
    c = r.contact[0]
    dev = {name: np.abs(_deviation(name, r)).sum(-1)[c].mean() for name in LIGHTS}
    assert dev["uniform"] < 0.35 * dev["zones3"] and dev["uniform"] < 0.35 * dev["sides4"], dev
    grey = _deviation("uniform", r)[c]
    assert np.abs(grey - grey.mean(-1, keepdims=True)).max() <= 2.0  # white light: no colour


def test_four_sides_light_the_press_from_four_sides() -> None:
    """Red comes from the right, green from the top, blue from the left, white from the bottom:
    each channel brightens the side of the cap that faces its light."""
    s = sensor(*SIZE, MPP, lights="sides4")
    centre = (slice(None), SIZE[0] // 2, SIZE[1] // 2)
    az = np.degrees(np.arctan2(-s.light[:, 1][centre], s.light[:, 0][centre])) % 360
    np.testing.assert_allclose(az, [0, 90, 180, 270], atol=1.0)
    (cx, cy), r = (83.3, 57.6), _press()[1]
    dev = _deviation("sides4", r)
    c = r.contact[0]
    yy, xx = np.mgrid[:SIZE[0], :SIZE[1]]
    right, left = c & (xx > cx + 3), c & (xx < cx - 3)
    top, bottom = c & (yy < cy - 3), c & (yy > cy + 3)
    assert dev[right, 0].mean() > dev[left, 0].mean() + 20  # red from the right
    assert dev[left, 2].mean() > dev[right, 2].mean() + 20  # blue from the left
    grey_bottom = dev[bottom].sum(-1).mean() - dev[top].sum(-1).mean()
    assert grey_bottom > 0  # white from the bottom: every channel
    assert dev[top, 1].mean() - dev[bottom, 1].mean() > dev[top, 0].mean() - dev[bottom, 0].mean()


@pytest.mark.parametrize("lights", list(LIGHTS))
@pytest.mark.parametrize("gel", ["none", "markers"])
@pytest.mark.parametrize("size", [(160, 208), (208, 160)])
def test_a_press_is_found_under_each_layout(lights, gel, size) -> None:
    """The contact circle of a press (0.4 mm deep, 30 px at 0.05 mm/px) shot through each
    layout, plain or through the marker gel's pattern and camera (JPEG, dust), within 1.5 px
    and 6 % of the exact one (the radius of a disc of the contact's area)."""
    mpp = 0.05
    app = sensor_appearance("markers")
    if gel == "none":
        app = dataclasses.replace(app, marker_share=0.0)
    centre = (size[1] * 0.52 + 0.3, size[0] * 0.47 - 0.4)
    _, truth = _press(size, centre, 0.4, mpp)
    fields = sensor(*size, mpp, lights=lights)
    cap = Capture(gel=2)
    bg = background(app, fields, cap, np.random.default_rng(1))
    img = relight(truth.grad, fields, cap, np.random.default_rng(2), app)[0]
    r = math.sqrt(truth.contact[0].sum() / math.pi)
    found = detect_circle(img, bg, ball_px=3.0 / mpp)
    assert found is not None
    x, y, fr = found
    assert math.hypot(x - centre[0], y - centre[1]) < 1.5 and abs(fr / r - 1) < 0.06, (found, r)
