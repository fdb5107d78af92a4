"""The background: one estimated from the presses is said to be untrustworthy where half or more
of them touch one spot (the median there is a press), and quiet where they are spread; a given
one that shows a contact the presses do not (a press frame) is named."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from tests.fixtures.calibration import save_presses
from vtsbench.depth.background import crowded, press_median
from vtsbench.depth.calibration import load_presses
from vtsbench.recordings.manifest import Circle, Entry, Source
from vtsbench.recordings.media import write_png
from vtsbench.sim.appearance import background, sensor_appearance
from vtsbench.sim.optics import Capture, sensor
from vtsbench.sim.plan import press_scene
from vtsbench.sim.scene import render

SIZE, MPP = (240, 320), 0.05


def test_crowded_finds_where_half_the_circles_overlap() -> None:
    shape = (100, 120)
    spread = [(20.0, 20.0, 8.0), (90.0, 25.0, 8.0), (30.0, 80.0, 8.0), (95.0, 75.0, 8.0)]
    assert crowded(shape, spread, 4) is None
    clustered = [(60.0, 50.0, 10.0), (63.0, 50.0, 10.0), (60.0, 54.0, 9.0), (20.0, 20.0, 8.0)]
    n, (x, y) = crowded(shape, clustered, 4)
    assert n == 3 and math.hypot(x - 61, y - 51) < 3
    # the share is of the frames the median was taken over, dropped presses included
    assert crowded(shape, clustered, 7) is None
    # a circle half off the frame counts where it lies; nothing, or no finite circle, is quiet
    assert crowded(shape, [(-5.0, 50.0, 10.0)] * 2, 2) == (2, (2, 50))
    assert crowded(shape, [], 5) is None
    assert crowded(shape, [(math.nan, 1.0, 2.0), (1.0, 1.0, math.inf)], 2) is None


def test_press_median_is_the_per_pixel_median() -> None:
    frames = [np.full((4, 5, 3), v, np.uint8) for v in (10, 200, 30)]
    assert (press_median(frames) == 30).all()


def _presses(folder: Path, spread_px: float, n: int = 8) -> Path:
    """n simulated presses of the 3 mm ball, centred within spread_px of the frame's centre,
    with their exact circles; the no-contact frame as bg.png, not in the manifest."""
    app = sensor_appearance("plain")
    rng = np.random.default_rng(1)
    (folder / "p").mkdir(parents=True)
    entries = []
    for i in range(n):
        scene = press_scene(np.random.default_rng(50 + i), SIZE, MPP, 2, app)
        cx = (SIZE[1] - 1) / 2 + rng.uniform(-spread_px, spread_px)
        cy = (SIZE[0] - 1) / 2 + rng.uniform(-spread_px, spread_px) * SIZE[0] / SIZE[1]
        shot = render(dataclasses.replace(scene, centers_px=((cx, cy),)), Capture(gel=1),
                      np.random.default_rng(i))
        write_png(folder / "p" / f"{i}.png", shot.frames[0])
        r = math.sqrt(float(shot.contact[0].sum()) / math.pi)
        entries.append(Entry(f"p{i}", "press", "s0", Source(f"p/{i}.png"), ball_radius_mm=3.0,
                             circle=Circle(cx, cy, r)))
    write_png(folder / "bg.png", background(app, sensor(*SIZE, MPP), Capture(gel=1),
                                            np.random.default_rng(99)))
    save_presses(folder, entries, SIZE, MPP)
    return folder


@pytest.mark.parametrize("spread_px, said", [(8.0, True), (120.0, False)])
def test_calibration_says_when_the_presses_crowd_the_estimated_background(
        tmp_path, spread_px, said) -> None:
    rec = _presses(tmp_path / "rec", spread_px)
    _, _, _, warns = load_presses(rec, estimate_background=True)
    hit = [w for w in warns if "the median there is a press" in w]
    assert bool(hit) == said, warns
    if said:
        assert "of 8 touch" in hit[0] and "--background FILE" in hit[0]


def _own(warns: list[str]) -> list[str]:
    return [w for w in warns if "shows a contact of its own" in w]


def test_a_press_frame_given_as_the_background_is_named(tmp_path) -> None:
    """A press frame as the background: its contact is named where it lies; the true
    background is quiet."""
    rec = _presses(tmp_path / "rec", 120.0)
    _, _, setup, warns = load_presses(rec, background=rec / "bg.png")
    assert not _own(warns), warns
    _, _, _, warns = load_presses(rec, background=rec / "p" / "0.png")
    hit = _own(warns)
    assert len(hit) == 1, warns
    c = next(p["label"] for p in setup["presses"] if p["id"] == "p0")
    x, y = (float(v) for v in hit[0].split(" at (")[1].split(")")[0].split(", "))
    assert math.hypot(x - c["x"], y - c["y"]) < 3, hit


def test_the_true_background_is_quiet_where_every_press_touches(tmp_path) -> None:
    """Every press within 8 px of the centre: their median is a press there and the true
    background differs from it by a contact, but the presses differ from it too (each in its
    own place and depth), so the background is not taken for a press frame."""
    rec = _presses(tmp_path / "rec", 8.0)
    _, _, _, warns = load_presses(rec, background=rec / "bg.png")
    assert not _own(warns), warns


def test_the_contact_sheet_says_what_is_wrong_with_the_background(tmp_path) -> None:
    """A run whose background is a press frame: its note is on the run and in red under the
    contact sheet's title (the tiles all look wrong, the note says why)."""
    from vtsbench.depth.calibration import calibrate
    from vtsbench.depth.report import contact_sheet
    from vtsbench.recordings.media import read_image

    rec = _presses(tmp_path / "rec", 120.0)
    run = calibrate(rec, method="poly", holdout=2, background=rec / "p" / "0.png")
    assert len(run.background_notes) == 1 and run.background_notes[0] in run.warnings
    said = read_image(contact_sheet(run, tmp_path / "said.png"))
    quiet = read_image(contact_sheet(dataclasses.replace(run, background_notes=[]),
                                     tmp_path / "quiet.png"))
    assert said.shape[0] > quiet.shape[0] and said.shape[1] == quiet.shape[1]

    def red(img: np.ndarray) -> int:
        band = img[: img.shape[0] // 8].astype(int)
        return int(((band[..., 0] > 200) & (band[..., 1] < 60) & (band[..., 2] < 60)).sum())

    assert red(said) > 200 and red(quiet) == 0
    assert calibrate(rec, method="poly", holdout=2, background=rec / "bg.png"
                     ).background_notes == []


def test_a_background_in_the_other_channel_order_is_named(tmp_path) -> None:
    """The background saved with its channels reversed (BGR for RGB): named with both
    distances; the presses' own order is quiet, and so is a grey gel, where order is moot."""
    from vtsbench.depth.background import channels_reversed
    from vtsbench.recordings.media import read_image

    rec = _presses(tmp_path / "rec", 120.0)
    bg = read_image(rec / "bg.png")
    write_png(rec / "bgr.png", np.ascontiguousarray(bg[..., ::-1]))
    _, _, _, warns = load_presses(rec, background=rec / "bgr.png")
    hit = [w for w in warns if "colour channels in the other order" in w]
    assert len(hit) == 1 and not _own(warns), warns
    _, _, _, warns = load_presses(rec, background=rec / "bg.png")
    assert not [w for w in warns if "other order" in w]
    grey = np.full((8, 8, 3), 120, np.uint8)
    assert channels_reversed(grey, grey + 10) is None  # 30 DN off either way
    given, rev = channels_reversed(np.dstack([grey[..., 0] + 40, grey[..., 1], grey[..., 2]]),
                                   np.dstack([grey[..., 0], grey[..., 1], grey[..., 2] + 40]))
    assert (given, rev) == (80.0, 0.0)
