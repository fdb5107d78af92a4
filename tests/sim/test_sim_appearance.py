"""Generator 2 appearance: the gel's fixed pattern (markers, border, dust), the imprint's gain and
the camera (compression, start-of-stream jump, drift); scenes without it render as before."""

from __future__ import annotations

import dataclasses
import hashlib

import numpy as np
import pytest

from vtsbench.sim.appearance import Appearance, background, capture
from vtsbench.sim.camera import compress, draw_take, gel_gain
from vtsbench.sim.optics import Capture, sensor
from vtsbench.sim.pattern import gel_pattern, has_markers
from vtsbench.sim.plan import EntryPlan, sequence_plan_scene
from vtsbench.sim.scene import render

SIZE = (96, 128)
MPP = 0.1
#: Nothing but the option under test: no pattern, no compression, no jump, no drift.
BARE = Appearance(marker_share=0.0, border_darkness=(0.0, 0.0), dust_per_cm2=0.0, scratches=0,
                  imprint_gain=(1.0, 1.0), jpeg_quality=None, wb_jump_share=0.0, drift=0.0,
                  refresh=0.0, noise_scale=1.0, keyframe_interval=None, grain=0.0)
NO_PATCH = (None, slice(0, 0), slice(0, 0))


def _fields():
    return sensor(SIZE[0], SIZE[1], MPP)


def _grey(frames: np.ndarray) -> np.ndarray:
    return frames.astype(np.float64).mean(axis=-1)


def test_markers_fixed_without_surface_displacement() -> None:
    app = dataclasses.replace(BARE, marker_share=1.0)
    frames = capture(app, _fields(), Capture(), None, [NO_PATCH] * 3, None)
    assert (frames == frames[0]).all()
    flat = capture(BARE, _fields(), Capture(), None, [NO_PATCH], None)[0]
    ratio = _grey(frames[0]) / _grey(flat)
    dark = ratio < 0.5  # inside the dots (centre darkness 0.75)
    share = np.pi * (app.marker_diameter_mm / 2) ** 2 / app.marker_pitch_mm ** 2
    assert dark.mean() == pytest.approx(share, rel=0.35)
    assert ratio.min() == pytest.approx(1 - app.marker_darkness, abs=0.03)


def test_markers_and_dust_ride_a_known_surface_displacement() -> None:
    app = dataclasses.replace(BARE, marker_share=1.0, dust_per_cm2=50.0)
    shift = np.zeros((2, *SIZE, 2), np.float32)
    shift[1, ..., 0], shift[1, ..., 1] = 3.0, -2.0  # the whole surface: 3 px right, 2 px up
    frames = capture(app, _fields(), Capture(), None, [NO_PATCH] * 2, shift)
    pattern = gel_pattern(app, 0, SIZE[0], SIZE[1], MPP)
    moved = np.roll(pattern.surface, (-2, 3), axis=(0, 1))
    assert np.allclose(pattern.surface[10:-10, 10:-10], moved[8:-12, 13:-7])  # roll check
    flat = capture(BARE, _fields(), Capture(), None, [NO_PATCH], None)[0]
    seen = _grey(frames) / _grey(flat)[None]
    inner = (slice(10, -10), slice(10, -10))
    assert np.abs(seen[1][inner] - moved[inner]).max() < 0.03
    assert np.abs(seen[0][inner] - pattern.surface[inner]).max() < 0.03
    assert np.abs(seen[1][inner] - seen[0][inner]).max() > 0.3  # it did move


def test_border_and_dust_off_the_moving_region_stay_fixed() -> None:
    app = dataclasses.replace(BARE, border_darkness=(0.08, 0.08), dust_per_cm2=50.0)
    shift = np.zeros((3, *SIZE, 2), np.float32)
    shift[1:, 40:60, 50:80] = 2.5  # only the middle of the gel moves
    frames = capture(app, _fields(), Capture(), None, [NO_PATCH] * 3, shift)
    still = np.ones(SIZE, bool)
    still[36:64, 46:84] = False
    assert (frames[1][still] == frames[0][still]).all()
    assert (frames[2] == frames[1]).all()
    flat = capture(BARE, _fields(), Capture(), None, [NO_PATCH], None)[0]
    ratio = _grey(frames[0]) / _grey(flat)
    assert ratio[SIZE[0] // 2, 0] == pytest.approx(0.92, abs=0.01)  # border band: 8 % darker
    pattern = gel_pattern(app, 0, SIZE[0], SIZE[1], MPP)
    assert (pattern.surface < 0.97).sum() > 10  # dust specks are there


def _imprint_scene():
    rng = np.random.default_rng(5)
    scene, _ = sequence_plan_scene(EntryPlan("sequence", 1, 0, "sphere", "static"), rng,
                                   SIZE, MPP, 2)
    return dataclasses.replace(scene, effects=dataclasses.replace(scene.effects, noise=False))


def test_imprint_gain_scales_the_deviation_from_flat() -> None:
    scene = _imprint_scene()
    full = render(dataclasses.replace(scene, appearance=BARE)).frames[0].astype(float)
    half_app = dataclasses.replace(BARE, imprint_gain=(0.5, 0.5))
    half = render(dataclasses.replace(scene, appearance=half_app)).frames[0].astype(float)
    flat = capture(BARE, _fields(), Capture(), None, [NO_PATCH], None)[0].astype(float)
    dev_full, dev_half = full - flat, half - flat
    assert np.abs(dev_full).max() > 20
    assert np.abs(dev_half - 0.5 * dev_full).max() <= 1.0  # rounding of both frames
    assert gel_gain(Appearance(imprint_gain=(0.25, 1.0)), 3) == pytest.approx(
        gel_gain(Appearance(imprint_gain=(0.25, 1.0)), 3))
    gains = [gel_gain(Appearance(), g) for g in range(12)]
    assert 0.25 <= min(gains) < 0.35 and 0.8 < max(gains) <= 1.0  # spread over the range


def test_compression_lowers_temporal_noise_of_still_pixels() -> None:
    frames = {}
    for q in (None, (70, 70)):
        app = dataclasses.replace(BARE, jpeg_quality=q)
        frames[q] = capture(app, _fields(), Capture(read_noise=1.5), np.random.default_rng(0),
                            [NO_PATCH] * 8, None)
    noise = {q: np.sqrt(_grey(f).var(axis=0, ddof=1).mean()) for q, f in frames.items()}
    assert noise[None] > 0.8
    assert noise[(70, 70)] < 0.1
    # a block that changes is sent again
    moving = frames[None].copy()
    moving[4:, 16:32, 16:32] += 30
    out = compress(moving, 70, 2.5)
    assert np.abs(_grey(out[5])[16:32, 16:32] - _grey(out[3])[16:32, 16:32]).mean() > 20
    # still blocks re-sent anyway at the refresh share: the noise of those comes back
    out = compress(frames[None], 70, 2.5, 0.3, np.random.default_rng(0))
    blocks = np.abs(np.diff(out.astype(int), axis=0)).max(axis=-1).reshape(7, 6, 16, 8, 16)
    assert blocks.max(axis=(2, 4)).astype(bool).mean() == pytest.approx(0.3, abs=0.07)


def test_white_balance_jump_only_at_the_start() -> None:
    app = dataclasses.replace(BARE, wb_jump_share=1.0)
    frames = capture(app, _fields(), Capture(), np.random.default_rng(1), [NO_PATCH] * 6, None)
    means = frames.reshape(6, -1, 3).astype(float).mean(axis=1)
    ref = means[2]
    assert np.abs(means[0] / ref - 1).max() > 0.02  # the first frame has other gains
    assert np.abs(means[1] / ref - 1).max() <= 0.031  # the second has nearly settled
    assert np.abs(means[2:] - ref).max() < 0.2  # then nothing changes but the noise
    never = capture(BARE, _fields(), Capture(), np.random.default_rng(1), [NO_PATCH] * 6, None)
    m2 = never.reshape(6, -1, 3).astype(float).mean(axis=1)
    assert np.abs(m2 - m2[2]).max() < 0.2


def test_drift_is_bounded_and_starts_at_one() -> None:
    app = dataclasses.replace(BARE, drift=0.002)
    for i in range(50):
        take = draw_take(app, np.random.default_rng(i), 8)
        assert np.allclose(take.gains[0], 1.0)
        assert np.abs(take.gains - 1.0).max() <= 0.002 + 1e-6
    moved = [np.abs(draw_take(app, np.random.default_rng(i), 8).gains[-1] - 1).max()
             for i in range(20)]
    assert max(moved) > 0.001


def test_marker_gels_alternate_and_background_shows_the_pattern() -> None:
    app = Appearance(marker_share=0.5)
    assert [has_markers(app, g) for g in range(6)].count(True) == 3
    marker_gel = next(g for g in range(6) if has_markers(app, g))
    plain = dataclasses.replace(app, jpeg_quality=None)
    bg = background(plain, _fields(), Capture(gel=marker_gel), None)
    frame = capture(dataclasses.replace(plain, drift=0.0), _fields(), Capture(gel=marker_gel),
                    None, [NO_PATCH], None)[0]
    assert (bg == frame).all()
    assert (_grey(bg) < 0.5 * _grey(bg).max()).mean() > 0.05  # the dots are in it


def test_scene_without_appearance_renders_the_same_bytes() -> None:
    rng = np.random.default_rng(7)
    scene, _ = sequence_plan_scene(EntryPlan("sequence", 1, 0, "gear", "slip"), rng, SIZE, MPP, 4)
    assert scene.appearance is None
    frames = render(scene, Capture(read_noise=1.3), rng).frames
    # recorded before the appearance existed
    assert hashlib.sha256(frames.tobytes()).hexdigest() == \
        "7801b6cbfe1dd63c47c95971df6f3a3230e239ea8735686f3e78545393ffbc2c"


def test_a_generator_2_folder_is_one_sensor(tmp_path) -> None:
    """Every session of a folder wears the folder's gel (number: the seed; markers or plain as
    asked) with one imprint gain, so presses and entries share the depth calibration."""
    from vtsbench.errors import VtsError
    from vtsbench.recordings.manifest import load_manifest
    from vtsbench.recordings.media import read_image
    from vtsbench.sim.appearance import sensor_appearance
    from vtsbench.sim.simulate import simulate

    flat = _grey(capture(BARE, _fields(), Capture(), None, [NO_PATCH], None)[0])
    for gel in ("markers", "plain"):
        out = tmp_path / gel
        simulate(out, seed=5, n_static=0, n_sequences=0, n_presses=0, n_objects=4, size=SIZE,
                 frames=2, n_sessions=3, mm_per_px=MPP, generator=2, gel=gel)
        pattern = gel_pattern(sensor_appearance(gel), 5, SIZE[0], SIZE[1], MPP)
        assert pattern.markers == (gel == "markers")
        notes = {s.notes.split("; read noise")[0] for s in load_manifest(out).sessions}
        assert len(notes) == 1 and f"{gel} gel, imprint gain" in notes.pop()
        bgs = [_grey(read_image(out / f"s{k:02d}" / "background.png")) / flat for k in range(3)]
        for bg in bgs:
            assert np.corrcoef(bg.ravel(), pattern.still.ravel())[0, 1] > 0.8
    with pytest.raises(VtsError, match="--gel"):
        simulate(tmp_path / "bad", n_static=1, n_sequences=0, n_presses=0, size=SIZE,
                 mm_per_px=MPP, generator=2, gel="dots")
    with pytest.raises(VtsError, match="--gel needs --generator 2"):
        simulate(tmp_path / "bad", n_static=1, n_sequences=0, n_presses=0, size=SIZE,
                 mm_per_px=MPP, generator=1, gel="plain")


def test_key_frames_send_the_whole_frame() -> None:
    """A key frame renews every block (and its noise); between key frames still blocks are
    kept; a take of 8 frames holds a key frame after its first in 7 of 12 streams."""
    still = capture(BARE, _fields(), Capture(read_noise=1.5), np.random.default_rng(0),
                    [NO_PATCH] * 6, None)
    out = compress(still, 70, 2.5, 0.0, None, keyframes=(4,))
    assert (out[1] == out[3]).all() and (out[5] == out[4]).all()
    changed = np.abs(out[4].astype(int) - out[3].astype(int)).max(axis=-1)
    assert changed.reshape(6, 16, 8, 16).max(axis=(1, 3)).astype(bool).mean() > 0.9
    app = dataclasses.replace(BARE, keyframe_interval=12)
    keys = [draw_take(app, np.random.default_rng(i), 8).keyframes for i in range(600)]
    assert all(len(k) <= 1 and all(1 <= t < 8 for t in k) for k in keys)
    assert np.mean([bool(k) for k in keys]) == pytest.approx(7 / 12, abs=0.06)
    assert draw_take(BARE, np.random.default_rng(0), 8).keyframes == ()


def test_grain_is_a_fixed_texture_of_the_gel() -> None:
    """The coating's grain multiplies the surface layer by 1 + grain * N(0, 1), the same in
    every call for a gel."""
    a = gel_pattern(dataclasses.replace(BARE, grain=0.0), 2, SIZE[0], SIZE[1], MPP)
    b = gel_pattern(dataclasses.replace(BARE, grain=0.01), 2, SIZE[0], SIZE[1], MPP)
    assert (a.surface == 1.0).all()
    assert np.std(b.surface) == pytest.approx(0.01, rel=0.1)
    c = gel_pattern(dataclasses.replace(BARE, grain=0.01, pattern_seed=0), 2, SIZE[0], SIZE[1],
                    MPP)
    assert (c.surface == b.surface).all()
