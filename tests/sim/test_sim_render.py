"""The renderer: exact truth, effects computed only when a scene needs them, sensible frames."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vtsbench.recordings.truth import Truth, read_truth, write_npz, write_truth
from vtsbench.sim import gel, optics
from vtsbench.sim.motion import hold, press, sequence_scene, slip
from vtsbench.sim.objects import BALL, GROUPS, OBJECTS, ObjectInstance, by_name, random_instance
from vtsbench.sim.plan import ball_contact_radius_mm, press_scene
from vtsbench.sim.scene import COUNTS, Effects, Scene, render

SIZE, MPP = (96, 128), 0.1


def scene_of(name: str, depth: float, effects: Effects | None = None, seed: int = 0,
             size: tuple[int, int] = SIZE, mpp: float = MPP) -> Scene:
    obj = random_instance(by_name(name), np.random.default_rng(seed))
    eff = effects or Effects(texture=obj.cls.texture is not None)
    return Scene(obj, ((size[1] / 2, size[0] / 2),), (depth,), size, mpp, eff)


def counts_of(scene: Scene) -> dict[str, int]:
    COUNTS.clear()
    render(scene, rng=np.random.default_rng(0))
    return {k: COUNTS[k] for k in ("geometry", "texture", "gel", "shade")}


# -- objects -------------------------------------------------------------------------------

def test_fifteen_classes_in_four_groups() -> None:
    assert len(OBJECTS) == 15 and len({c.name for c in OBJECTS}) == 15
    assert {c.group for c in OBJECTS} == set(GROUPS)
    assert {c.group for c in OBJECTS[:4]} == set(GROUPS)
    assert all(c.texture is not None for c in OBJECTS) and BALL.texture is None


@pytest.mark.parametrize("cls", OBJECTS, ids=lambda c: c.name)
def test_shapes_top_at_zero_and_textures_bounded(cls) -> None:
    obj = ObjectInstance(cls, 0.0, 1.0, np.random.default_rng(1).random(48))
    g = np.linspace(-cls.radius_mm, cls.radius_mm, 801)
    u, v = np.meshgrid(g, g)
    h = obj.shape(u, v)
    assert -0.02 < h.max() <= 1e-12
    outside = np.hypot(u, v) > cls.radius_mm
    assert (h[outside] < -100).all()
    t = obj.texture(u, v)
    assert t.dtype == np.float32
    assert np.abs(t).max() <= cls.texture_amp_mm * (1 + 1e-4)
    assert t.std() > 0


@pytest.mark.parametrize("cls", OBJECTS, ids=lambda c: c.name)
def test_every_class_makes_an_imprint(cls) -> None:
    r = render(scene_of(cls.name, np.mean(cls.depth_mm), seed=2), rng=np.random.default_rng(0))
    assert r.contact.sum() > 20
    bg = optics.sensor(*SIZE, MPP).flat
    diff = np.abs(r.frames[0].astype(np.float32) - bg).mean(axis=-1)
    assert diff[r.depth_mm[0] > 0.05].mean() > 8.0


# -- truth ---------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["cube", "fabric", "pin_header"])
def test_truth_depth_and_gradients(name: str) -> None:
    s = scene_of(name, 0.4)
    r = render(s, rng=np.random.default_rng(0))
    d = r.depth_mm[0].astype(np.float64)
    assert (d >= 0).all() and d.max() > 0.3
    gy, gx = np.gradient(d, MPP)
    np.testing.assert_allclose(r.grad[0, ..., 0], gx, atol=2e-5)
    np.testing.assert_allclose(r.grad[0, ..., 1], gy, atol=2e-5)
    assert (r.contact[0] <= (d > 0)).all()


def test_depth_is_zero_far_from_contact() -> None:
    s = scene_of(BALL.name, 0.3, Effects(texture=False))
    r = render(s, rng=np.random.default_rng(0))
    a = ball_contact_radius_mm(0.3) / MPP
    yy, xx = np.mgrid[0:SIZE[0], 0:SIZE[1]]
    dist = np.hypot(xx - SIZE[1] / 2, yy - SIZE[0] / 2)
    far = dist > a + gel.margin_px(MPP) * math.sqrt(2) + 2  # separable kernels: square support
    assert far.any() and (r.depth_mm[0][far] == 0).all() and (r.grad[0][far] == 0).all()
    assert (r.depth_mm[0][dist < a / 2] > 0).all()


def test_press_circle_matches_contact_and_depth_below_radius() -> None:
    for seed in range(4):
        s = press_scene(np.random.default_rng(seed), (120, 160), 0.05)
        r = render(s, rng=np.random.default_rng(0))
        c = r.contact[0]
        cx, cy = s.centers_px[0]
        rad = math.sqrt(c.sum() / math.pi)
        yy, xx = np.nonzero(c)
        dist = np.hypot(xx - cx, yy - cy)
        assert dist.max() <= rad + 1.5  # a disc about the ball's centre
        assert rad <= ball_contact_radius_mm(s.depths_mm[0]) / 0.05 + 0.5
        assert rad >= 0.7 * ball_contact_radius_mm(s.depths_mm[0]) / 0.05
        assert r.depth_mm.max() <= s.depths_mm[0] + 1e-6 < 3.0


def test_truth_npz_is_byte_deterministic_and_loadable(tmp_path) -> None:
    r = render(scene_of("gear", 0.3), rng=np.random.default_rng(0))
    truth = Truth(r.depth_mm, r.grad, r.contact, r.motion_px)
    write_truth(tmp_path / "a.npz", truth)
    write_truth(tmp_path / "b.npz", truth)
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()
    z = np.load(tmp_path / "a.npz")
    assert sorted(z.files) == ["box", "contact", "depth_mm", "grad", "motion_px", "shape",
                               "version"]
    assert z["depth_mm"].size < r.depth_mm.size  # stored cropped
    t = read_truth(tmp_path / "a.npz")
    for name in ("depth_mm", "grad", "contact", "motion_px"):
        np.testing.assert_array_equal(getattr(t, name), getattr(r, name))
    write_npz(tmp_path / "c.npz", {"x": np.arange(3)})
    assert np.load(tmp_path / "c.npz")["x"].tolist() == [0, 1, 2]


# -- effects -------------------------------------------------------------------------------

def test_held_sequence_computes_geometry_once() -> None:
    obj = random_instance(by_name("gear"), np.random.default_rng(0))
    s = sequence_scene(obj, hold(0.3), (64.0, 48.0), 6, SIZE, MPP)
    assert not s.effects.motion
    assert counts_of(s) == {"geometry": 1, "texture": 1, "gel": 1, "shade": 1}
    r = render(s, rng=np.random.default_rng(0))
    assert (r.depth_mm == r.depth_mm[0]).all()
    assert not (r.frames == r.frames[0]).all()  # only the noise changes


def test_press_sequence_solves_the_gel_per_frame_on_one_geometry() -> None:
    obj = random_instance(by_name("cone"), np.random.default_rng(0))
    s = sequence_scene(obj, press(0.1, 0.6), (64.0, 48.0), 5, SIZE, MPP)
    assert counts_of(s) == {"geometry": 1, "texture": 1, "gel": 5, "shade": 5}
    r = render(s, rng=np.random.default_rng(0))
    peaks = r.depth_mm.reshape(5, -1).max(axis=1)
    assert (np.diff(peaks) > 0).all()


def test_slip_sequence_evaluates_geometry_per_frame() -> None:
    obj = random_instance(by_name("leaf"), np.random.default_rng(0))
    s = sequence_scene(obj, slip(30.0, 0.5, 0.4), (60.0, 50.0), 4, SIZE, MPP)
    assert s.effects.motion
    assert counts_of(s) == {"geometry": 4, "texture": 4, "gel": 4, "shade": 4}


def test_calibration_press_computes_no_texture() -> None:
    s = press_scene(np.random.default_rng(0), SIZE, MPP)
    assert not s.effects.texture
    assert counts_of(s)["texture"] == 0
    # A textured class with texture switched off computes none either.
    assert counts_of(scene_of("fabric", 0.4, Effects(texture=False)))["texture"] == 0
    assert counts_of(scene_of("fabric", 0.4))["texture"] == 1


def test_forcing_every_effect_computes_more_but_renders_the_same() -> None:
    obj = random_instance(by_name("hex_nut"), np.random.default_rng(0))
    s = sequence_scene(obj, hold(0.4), (64.0, 48.0), 3, SIZE, MPP)
    full = s.with_effects(Effects.everything())
    assert counts_of(full) == {"geometry": 3, "texture": 3, "gel": 3, "shade": 3}
    a = render(s, rng=np.random.default_rng(5))
    b = render(full, rng=np.random.default_rng(5))
    np.testing.assert_allclose(a.depth_mm, b.depth_mm, atol=1e-6)
    np.testing.assert_array_equal(a.contact, b.contact)
    assert np.abs(a.frames.astype(int) - b.frames).max() <= 1


def test_texture_changes_the_imprint() -> None:
    a = render(scene_of("wood", 0.4), rng=np.random.default_rng(0))
    b = render(scene_of("wood", 0.4, Effects(texture=False)), rng=np.random.default_rng(0))
    assert np.abs(a.depth_mm - b.depth_mm).max() > 0.01


def test_outside_the_box_is_the_flat_image_plus_noise() -> None:
    s = scene_of(BALL.name, 0.15, Effects(texture=False, noise=False))
    r = render(s)
    fields = optics.sensor(*SIZE, MPP)
    flat = np.floor(fields.flat + 0.5).astype(np.uint8)
    untouched = (r.depth_mm[0] == 0)
    untouched[1:-1, 1:-1] &= (r.depth_mm[0][:-2, 1:-1] == 0) & (r.depth_mm[0][2:, 1:-1] == 0) \
        & (r.depth_mm[0][1:-1, :-2] == 0) & (r.depth_mm[0][1:-1, 2:] == 0)
    assert untouched.mean() > 0.6
    np.testing.assert_array_equal(r.frames[0][untouched], flat[untouched])
    # With noise: residuals outside the imprint have zero mean and the modelled deviation.
    cap = optics.Capture(read_noise=1.5)
    noisy = render(s.with_effects(Effects(texture=False)), cap, np.random.default_rng(3))
    res = noisy.frames[0].astype(np.float64) - fields.flat
    sigma = optics.noise_sigma(fields.flat, cap)
    z = res[untouched] / sigma[untouched]
    assert abs(z.mean()) < 0.05 and 0.9 < z.std() < 1.15


def test_the_background_follows_the_led_layout() -> None:
    f = optics.sensor(96, 128, 0.1).flat
    top, bottom = f[:20].mean(axis=(0, 1)), f[-20:].mean(axis=(0, 1))
    left, right = f[:, :20].mean(axis=(0, 1)), f[:, -20:].mean(axis=(0, 1))
    assert top[0] > bottom[0]  # red zone at the top
    assert left[1] > right[1]  # green zone at the lower left
    assert right[2] > left[2]  # blue zone at the lower right
    centre = f[40:56, 56:72].mean(axis=(0, 1))
    assert np.all(np.abs(centre - optics.FLAT_LEVEL) < 0.05 * optics.FLAT_LEVEL)
    uni = optics.sensor(96, 128, 0.1, vignetting=False, nonuniform=False).flat
    assert np.ptp(uni.reshape(-1, 3), axis=0).max() < 1e-3


def test_noise_lookup_is_unit_normal() -> None:
    n = optics.normal_field(np.random.default_rng(0), 96, 128)
    assert n.dtype == np.float32 and n.shape == (96, 128, 3)
    assert abs(n.mean()) < 0.02 and abs(n.std() - 1.0) < 0.02


def test_a_moving_scene_needs_the_motion_effect() -> None:
    obj = random_instance(BALL, np.random.default_rng(0))
    with pytest.raises(ValueError, match="motion"):
        Scene(obj, ((10.0, 10.0), (12.0, 10.0)), (0.2, 0.2), SIZE, MPP, Effects(motion=False))


def test_spread_off_leaves_no_skirt() -> None:
    on = render(scene_of(BALL.name, 0.4, Effects(texture=False)), rng=np.random.default_rng(0))
    off = render(scene_of(BALL.name, 0.4, Effects(texture=False, spread=False)),
                 rng=np.random.default_rng(0))
    a = ball_contact_radius_mm(0.4) / MPP
    yy, xx = np.mgrid[0:SIZE[0], 0:SIZE[1]]
    ring = np.hypot(xx - SIZE[1] / 2, yy - SIZE[0] / 2) > a + 2
    assert (off.depth_mm[0][ring] == 0).all()
    assert on.depth_mm[0][ring].max() > 0.01  # the skirt
    assert on.contact.sum() < off.contact.sum()  # the skirt term takes the contact's rim


def test_ideal_optics_effects_render_a_uniform_background() -> None:
    s = scene_of(BALL.name, 0.2, Effects(texture=False, noise=False, vignetting=False,
                                         nonuniform_light=False))
    r = render(s)
    far = r.depth_mm[0] == 0
    vals = r.frames[0][far].reshape(-1, 3)
    assert (vals == vals[0]).all()


def test_truth_without_contact_and_bad_files(tmp_path) -> None:
    z = np.zeros((2, 8, 10), np.float32)
    empty = Truth(z, np.zeros((2, 8, 10, 2), np.float32), z.astype(bool), np.zeros((2, 2)))
    write_truth(tmp_path / "e.npz", empty)
    back = read_truth(tmp_path / "e.npz")
    assert back.depth_mm.shape == (2, 8, 10) and not back.depth_mm.any()
    from vtsbench.errors import VtsError

    (tmp_path / "bad.npz").write_bytes(b"PK broken")
    with pytest.raises(VtsError, match="not a vtsbench truth file"):
        read_truth(tmp_path / "bad.npz")
    with pytest.raises(VtsError, match="not found"):
        read_truth(tmp_path / "missing.npz")
