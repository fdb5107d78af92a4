"""A background estimated from the presses: said to be untrustworthy where half or more of them
touch one spot (the median there is a press), and quiet where they are spread."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from vtsbench.depth.background import crowded, press_median
from vtsbench.depth.calibration import load_presses
from vtsbench.recordings.manifest import (
    Circle,
    Entry,
    Manifest,
    Mount,
    Session,
    Source,
    save_manifest,
)
from vtsbench.recordings.media import write_png
from vtsbench.sim.appearance import sensor_appearance
from vtsbench.sim.optics import Capture
from vtsbench.sim.plan import press_scene
from vtsbench.sim.scene import render

SIZE, MPP = (120, 160), 0.1


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
    with their exact circles and no background."""
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
    save_manifest(folder, Manifest(sessions=[Session("s0", "sim", SIZE, (MPP, MPP), 30.0, None,
                                                     mount=Mount())],
                                   entries=entries, name="p", description="p", created_by="t"))
    return folder


@pytest.mark.parametrize("spread_px, said", [(8.0, True), (60.0, False)])
def test_calibration_says_when_the_presses_crowd_the_estimated_background(
        tmp_path, spread_px, said) -> None:
    rec = _presses(tmp_path / "rec", spread_px)
    _, _, _, warns = load_presses(rec, estimate_background=True)
    hit = [w for w in warns if "the median there is a press" in w]
    assert bool(hit) == said, warns
    if said:
        assert "of 8 touch" in hit[0] and "--background FILE" in hit[0]
