"""Slip directions: labels from the motion that made the frames, exact at the bin boundaries."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vtsbench.labels import direction_class
from vtsbench.sim.motion import hold, press, sample_motion, sequence_scene, slip
from vtsbench.sim.objects import BALL, random_instance
from vtsbench.sim.scene import render


@pytest.mark.parametrize(("angle", "cls"), [
    (22.5, 1), (359.99, 0), (337.49, 7), (0.0, 0), (90.0, 2), (180.0, 4), (270.0, 6),
    (67.5, 2), (112.5, 3), (157.5, 4), (202.5, 5), (247.5, 6), (292.5, 7),
    # 337.5 is the lower edge of class 0 ([337.5, 22.5)), like every boundary in labels.py.
    (337.5, 0),
])
def test_explicit_slip_at_exact_angles(angle: float, cls: int) -> None:
    lab = slip(angle, 0.4, 0.5).label()
    assert lab.state == "slip" and lab.direction == cls


def test_zero_motion_is_static_without_direction() -> None:
    lab = slip(123.0, 0.0, 0.5).label()
    assert (lab.state, lab.direction, lab.motion_mm) == ("static", None, (0.0, 0.0))
    assert hold(0.4).label().state == "static"
    assert press(0.2, 0.5).label().state == "press"
    assert press(0.2, 0.5).label().direction is None


def test_sampled_slips_are_labelled_by_their_angle() -> None:
    rng = np.random.default_rng(0)
    for _ in range(300):
        m = sample_motion("slip", rng, (0.2, 1.0))
        lab = m.label()
        assert 0.08 - 1e-12 <= math.hypot(m.dx_mm, m.dy_mm) <= 1.5 + 1e-12
        assert lab.state == "slip" and lab.direction == direction_class(m.dx_mm, m.dy_mm)
    for _ in range(50):
        m = sample_motion("press", rng, (0.2, 1.0))
        assert m.label().state == "press" and 0.2 <= m.depth1_mm <= 1.0
        assert m.depth1_mm - m.depth0_mm >= 0.08 - 1e-12 and m.depth0_mm > 0


@pytest.mark.parametrize("angle", [10.0, 100.0, 200.0, 300.0])
def test_the_imprint_moves_the_labelled_way(angle: float) -> None:
    size, mpp = (96, 128), 0.05
    obj = random_instance(BALL, np.random.default_rng(0))
    motion = slip(angle, 1.2, 0.3)
    scene = sequence_scene(obj, motion, (64.0 - 12 * math.cos(math.radians(angle)),
                                         48.0 + 12 * math.sin(math.radians(angle))), 3, size,
                           mpp)
    r = render(scene, rng=np.random.default_rng(1))
    ys, xs = np.nonzero(r.depth_mm[0] > 0.05)
    ye, xe = np.nonzero(r.depth_mm[-1] > 0.05)
    dx, dy_up = (xe.mean() - xs.mean()) * mpp, -(ye.mean() - ys.mean()) * mpp
    assert direction_class(dx, dy_up) == motion.label().direction
    assert math.hypot(dx, dy_up) == pytest.approx(1.2, abs=0.05)
