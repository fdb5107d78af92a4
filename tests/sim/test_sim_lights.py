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


@pytest.mark.parametrize("lights", ["sides4", "uniform"])
def test_a_simulated_folder_is_shot_through_its_light_layout(tmp_path, lights) -> None:
    """`simulate(..., lights=)`: each press frame is its exact truth shot through that layout
    (the same draws as the default's render), the sensor is named for the layout, and the
    geometry is the default layout's."""
    from vtsbench.recordings.manifest import load_manifest
    from vtsbench.recordings.media import read_image
    from vtsbench.recordings.truth import read_truth
    from vtsbench.sim.plan import entry_rng
    from vtsbench.sim.simulate import simulate

    kw = {"seed": 5, "n_static": 0, "n_sequences": 0, "n_presses": 2, "size": SIZE,
          "mm_per_px": MPP, "n_sessions": 1, "gel": "markers"}
    simulate(tmp_path / "lit", lights=lights, **kw)
    simulate(tmp_path / "default", **kw)
    m, d = load_manifest(tmp_path / "lit"), load_manifest(tmp_path / "default")
    assert [s.sensor for s in m.sessions] == [f"vtsbench-sim-{lights}"]
    assert d.sessions[0].sensor == "vtsbench-sim" and m.sessions[0].notes.endswith(lights)
    fields, app = sensor(*SIZE, MPP, lights=lights), sensor_appearance("markers")
    cap = Capture(read_noise=float(m.sessions[0].notes.split("read noise ")[1].split(" DN")[0]),
                  gel=5)
    for e, e0 in zip(m.entries, d.entries, strict=True):
        truth = read_truth(tmp_path / "lit" / e.truth)
        assert np.array_equal(truth.depth_mm, read_truth(tmp_path / "default" / e0.truth).depth_mm)
        rng = entry_rng(5, "press", int(e.id.split("-")[1]))
        press_scene(rng, SIZE, MPP, 2, app)  # the draws the scene takes before its frame
        want = relight(truth.grad, fields, cap, rng, app)[0]
        frame = read_image(tmp_path / "lit" / e.source.path)
        assert np.array_equal(frame, want)
        assert not np.array_equal(frame, read_image(tmp_path / "default" / e0.source.path))


def test_the_command_line_offers_every_layout(tmp_path) -> None:
    """`vtsbench simulate --lights` lists exactly the layouts of `optics.LIGHTS`, and writes one."""
    import typing

    from typer.testing import CliRunner

    from vtsbench.cli import app
    from vtsbench.cli.recordings import simulate as command
    from vtsbench.recordings.manifest import load_manifest

    hint = typing.get_type_hints(command, include_extras=True)["lights"]
    assert set(typing.get_args(typing.get_args(hint)[0])) == set(LIGHTS)
    out = tmp_path / "rec"
    r = CliRunner().invoke(app, ["simulate", str(out), "--lights", "sides4", "--static", "0",
                                 "--sequences", "0", "--presses", "1", "--size", "96x128",
                                 "--sessions", "1", "--quiet"])
    assert r.exit_code == 0, r.output
    assert load_manifest(out).sessions[0].sensor == "vtsbench-sim-sides4"
