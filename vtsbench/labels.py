"""Label conventions shared by every stage: contact states, slip-direction bins, motion labelling.

Directions follow the project convention: the angle of the imprint's motion across the image,
counter-clockwise from +x (image right) with y pointing UP the image. Class k in 0..7 covers
[45k - 22.5, 45k + 22.5) degrees wrapped to [0, 360): 0 = right, 2 = up, 4 = left, 6 = down.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

STATES: tuple[str, ...] = ("static", "press", "slip")
N_DIRECTIONS = 8
BIN_DEG = 360.0 / N_DIRECTIONS
DIRECTION_NAMES: tuple[str, ...] = ("right", "up-right", "up", "up-left", "left", "down-left",
                                    "down", "down-right")
# Angles are rounded to this many decimals before binning, so that a motion built at exactly a
# bin boundary (22.5 deg) lands in the upper bin despite the last-bit error of atan2.
ANGLE_DECIMALS = 9

#: Default thresholds (mm over one window) that separate static, press and slip.
SLIP_THRESHOLD_MM = 0.05
PRESS_THRESHOLD_MM = 0.05


def motion_angle_deg(dx: float, dy: float) -> float:
    """Angle of an image-frame motion (x right, y up) in degrees in [0, 360)."""
    ang = round(math.degrees(math.atan2(dy, dx)), ANGLE_DECIMALS) % 360.0
    return 0.0 if ang >= 360.0 else ang


def angle_to_class(angle_deg: float) -> int:
    """Direction class of an angle: k covers [45k - 22.5, 45k + 22.5) wrapped to [0, 360)."""
    if not math.isfinite(angle_deg):
        raise ValueError(f"angle must be finite, got {angle_deg}")
    a = round(angle_deg, ANGLE_DECIMALS)
    return math.floor(((a + BIN_DEG / 2) % 360.0) / BIN_DEG) % N_DIRECTIONS


def direction_class(dx: float, dy: float, min_mm: float = SLIP_THRESHOLD_MM) -> int | None:
    """Direction class of an image-frame motion in mm, or None when it is shorter than min_mm."""
    if math.hypot(dx, dy) < min_mm:
        return None
    return angle_to_class(motion_angle_deg(dx, dy))


def class_center_deg(k: int) -> float:
    """Centre angle of direction class k in degrees."""
    return (k % N_DIRECTIONS) * BIN_DEG


#: Direction class after mirroring the image left-right (angle a -> 180 - a) and up-down
#: (a -> -a). Exact for every angle inside a bin; a motion exactly on a bin edge (22.5 deg)
#: would land in the neighbouring bin, a set of measure zero.
MIRROR_X: tuple[int, ...] = tuple((4 - k) % N_DIRECTIONS for k in range(N_DIRECTIONS))
MIRROR_Y: tuple[int, ...] = tuple((-k) % N_DIRECTIONS for k in range(N_DIRECTIONS))


@dataclass(frozen=True)
class Thresholds:
    """Window-level thresholds (mm) separating static, press and slip."""

    slip_mm: float = SLIP_THRESHOLD_MM
    press_mm: float = PRESS_THRESHOLD_MM


@dataclass(frozen=True)
class MotionLabel:
    """Labels derived from the motion that produced a window."""

    state: str | None
    direction: int | None
    motion_mm: tuple[float, float]


def label_motion(dx_mm: float, dy_mm: float, dz_mm: float,
                 thresholds: Thresholds = Thresholds()) -> MotionLabel:
    """Label a window from its image-frame displacement (x right, y up) and indentation change.

    slip: lateral displacement >= slip_mm (direction from its angle);
    press: otherwise, indentation rising by >= press_mm;
    static: otherwise, |indentation change| < press_mm;
    None (unknown): indentation falling by >= press_mm (a release is none of the three states).
    """
    lateral = math.hypot(dx_mm, dy_mm)
    motion = (float(dx_mm), float(dy_mm))
    if lateral >= thresholds.slip_mm:
        return MotionLabel("slip", direction_class(dx_mm, dy_mm, thresholds.slip_mm), motion)
    if dz_mm >= thresholds.press_mm:
        return MotionLabel("press", None, motion)
    if dz_mm <= -thresholds.press_mm:
        return MotionLabel(None, None, motion)
    return MotionLabel("static", None, motion)


def label_contact_window(positions_mm: Sequence[tuple[float, float]],
                         depths_mm: Sequence[float], in_contact: Sequence[bool],
                         thresholds: Thresholds = Thresholds()) -> MotionLabel:
    """Label a window in which contact may be made or lost, from the object's commanded motion.

    The lateral motion is the object's displacement (image frame, x right, y up) between the
    first and the last frame in contact (what the imprint shows); the indentation change is
    max(0, last depth) - max(0, first depth) (a depth below 0 is the object above the gel).
    Then label_motion applies: contact made without slip is a press (when the final indentation
    reaches press_mm), contact lost without slip a release (unknown), either with a slip while
    in contact a slip in that direction. A window with no contact at all is unknown.
    """
    frames = [i for i, c in enumerate(in_contact) if c]
    if not frames:
        return MotionLabel(None, None, (0.0, 0.0))
    (x0, y0), (x1, y1) = positions_mm[frames[0]], positions_mm[frames[-1]]
    dz = max(0.0, depths_mm[-1]) - max(0.0, depths_mm[0])
    return label_motion(x1 - x0, y1 - y0, dz, thresholds)
