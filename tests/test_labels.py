"""Direction bins and motion labelling follow the project conventions exactly."""

import math

import pytest

from vtsbench.labels import (
    Thresholds,
    angle_to_class,
    class_center_deg,
    direction_class,
    label_motion,
    motion_angle_deg,
)


@pytest.mark.parametrize(("angle", "cls"), [
    (0.0, 0), (22.4999, 0), (22.5, 1), (45.0, 1), (67.5, 2), (90.0, 2), (180.0, 4), (270.0, 6),
    (337.4999, 7), (337.5, 0), (292.5, 7), (292.4999, 6), (359.99, 0), (360.0, 0), (-22.5, 0),
    (-22.5001, 7), (720.0, 0),
])
def test_angle_bins_including_boundaries(angle: float, cls: int) -> None:
    assert angle_to_class(angle) == cls


@pytest.mark.parametrize("k", range(8))
def test_vectors_built_on_every_boundary_land_in_the_upper_bin(k: int) -> None:
    a = math.radians(45 * k + 22.5)
    assert direction_class(math.cos(a), math.sin(a)) == (k + 1) % 8
    c = math.radians(class_center_deg(k))
    assert direction_class(math.cos(c), math.sin(c)) == k


def test_image_frame_is_y_up() -> None:
    assert direction_class(1.0, 0.0) == 0
    assert direction_class(0.0, 1.0) == 2  # up the image
    assert direction_class(-1.0, 0.0) == 4
    assert direction_class(0.0, -1.0) == 6
    assert motion_angle_deg(1.0, -1e-12) == 0.0 or motion_angle_deg(1.0, -1e-12) > 359.0


def test_short_and_zero_motion_have_no_direction() -> None:
    assert direction_class(0.0, 0.0) is None
    assert direction_class(0.01, 0.0, min_mm=0.05) is None
    lab = label_motion(0.0, 0.0, 0.0)
    assert (lab.state, lab.direction) == ("static", None)


def test_label_motion_states_and_thresholds() -> None:
    t = Thresholds(slip_mm=0.1, press_mm=0.2)
    assert label_motion(0.1, 0.0, 0.0, t).state == "slip"
    assert label_motion(0.0999, 0.0, 0.0, t).state == "static"
    assert label_motion(0.0, 0.0, 0.2, t).state == "press"
    assert label_motion(0.0, 0.0, 0.1999, t).state == "static"
    assert label_motion(0.0, 0.0, -0.2, t).state is None  # a release is none of the states
    slip = label_motion(-0.3, -0.3, 0.5, t)  # slip wins over a simultaneous press
    assert (slip.state, slip.direction) == ("slip", 5)


def test_non_finite_angle_is_an_error() -> None:
    with pytest.raises(ValueError):
        angle_to_class(float("nan"))


@pytest.mark.parametrize("angle", [0.0, 10.0, 44.0, 67.0, 100.0, 135.0, 200.0, 290.0, 359.0])
def test_mirror_tables_follow_the_mirrored_angle(angle: float) -> None:
    from vtsbench.labels import MIRROR_X, MIRROR_Y

    k = angle_to_class(angle)
    assert MIRROR_X[k] == angle_to_class((180.0 - angle) % 360.0)
    assert MIRROR_Y[k] == angle_to_class((-angle) % 360.0)
