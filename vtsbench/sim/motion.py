"""Sequence motion: the commanded displacement and depth of a held, pressed or slipping object.

Motions are in the image frame of the labels (x right, y UP, mm); the renderer's pixel frame
has y down the rows, so `centers` flips y. Labels come from `vtsbench.labels.label_motion` on
exactly the motion that places the object in the frames.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..labels import MotionLabel, label_motion
from .objects import ObjectInstance
from .scene import Effects, Scene

#: Total slip over a sequence (mm), drawn log-uniform: from just above the slip threshold.
SLIP_RANGE_MM = (0.08, 1.5)
#: Total indentation increase of a press sequence (mm), drawn log-uniform.
PRESS_RANGE_MM = (0.08, 0.8)
#: Generator 2's slip and press ranges (mm, log-uniform), from the motion of real GelSight
#: Mini windows (docs/simulator.md, "Generator 2: realistic slip").
SLIP_RANGE_V2_MM = (0.06, 0.4)
PRESS_RANGE_V2_MM = (0.08, 0.8)
#: Shallowest depth (mm) a press sequence starts from.
PRESS_START_MM = 0.02
#: Object centres stay in the central part of the frame: this share of it is kept clear.
BORDER_SHARE = 0.2


@dataclass(frozen=True)
class Motion:
    """Image-frame displacement (x right, y up, mm) over a sequence and its first/last depth."""

    dx_mm: float
    dy_mm: float
    depth0_mm: float
    depth1_mm: float
    #: Share of the lateral motion reached at each frame (None: constant speed).
    progress: tuple[float, ...] | None = None
    #: Depth per frame (None: linear from depth0_mm to depth1_mm); negative: above the gel.
    depth_path: tuple[float, ...] | None = None

    def label(self) -> MotionLabel:
        """State, direction and motion from the shared labelling rule."""
        return label_motion(self.dx_mm, self.dy_mm, self.depth1_mm - self.depth0_mm)

    def depths(self, n: int) -> tuple[float, ...]:
        """Depth per frame, linear from the first to the last (constant when equal)."""
        if self.depth_path is not None:
            if len(self.depth_path) != n:
                raise ValueError(f"the depth path has {len(self.depth_path)} frames, not {n}")
            return self.depth_path
        if self.depth0_mm == self.depth1_mm:
            return (self.depth0_mm,) * n
        return tuple(self.depth0_mm + (self.depth1_mm - self.depth0_mm) * i / (n - 1)
                     for i in range(n))

    def centers(self, start_px: tuple[float, float], n: int,
                mm_per_px: float) -> tuple[tuple[float, float], ...]:
        """Object centre per frame (px, y down the rows) from start_px, at constant velocity or
        along the motion's progress."""
        if self.dx_mm == 0.0 and self.dy_mm == 0.0:
            return (start_px,) * n
        x0, y0 = start_px
        ddx, ddy = self.dx_mm / mm_per_px, -self.dy_mm / mm_per_px
        if self.progress is not None:
            if len(self.progress) != n:
                raise ValueError(f"the progress has {len(self.progress)} frames, not {n}")
            return tuple((x0 + ddx * p, y0 + ddy * p) for p in self.progress)
        return tuple((x0 + ddx * i / (n - 1), y0 + ddy * i / (n - 1)) for i in range(n))

    def positions_mm(self, n: int) -> tuple[tuple[float, float], ...]:
        """Object displacement from the first frame per frame, image frame (x right, y up), mm."""
        prog = self.progress or tuple(i / (n - 1) for i in range(n))
        return tuple((self.dx_mm * p, self.dy_mm * p) for p in prog)


def hold(depth_mm: float) -> Motion:
    """The object held still."""
    return Motion(0.0, 0.0, depth_mm, depth_mm)


def press(depth0_mm: float, depth1_mm: float) -> Motion:
    """The object pressed further in without lateral motion."""
    return Motion(0.0, 0.0, depth0_mm, depth1_mm)


def slip(angle_deg: float, distance_mm: float, depth_mm: float) -> Motion:
    """The object sliding distance_mm at angle_deg (counter-clockwise from image right, y up)."""
    a = math.radians(angle_deg)
    return Motion(distance_mm * math.cos(a), distance_mm * math.sin(a), depth_mm, depth_mm)


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    """A log-uniform draw: as many small motions as large ones, per octave."""
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def slip_range(generator: int = 1) -> tuple[float, float]:
    """The slip distance range (mm) of a generator."""
    return SLIP_RANGE_V2_MM if generator >= 2 else SLIP_RANGE_MM


def sample_motion(state: str, rng: np.random.Generator, depth_range: tuple[float, float],
                  generator: int = 1) -> Motion:
    """A random motion of an intended state ('static', 'press' or 'slip'), in the ranges of
    its generator."""
    lo, hi = depth_range
    press_range = PRESS_RANGE_V2_MM if generator >= 2 else PRESS_RANGE_MM
    if state == "static":
        return hold(float(rng.uniform(lo, hi)))
    if state == "press":
        dz = min(_log_uniform(rng, *press_range), hi - PRESS_START_MM)
        d1 = float(rng.uniform(max(lo, dz + PRESS_START_MM), hi))
        return press(d1 - dz, d1)
    if state == "slip":
        angle = float(rng.uniform(0.0, 360.0))
        return slip(angle, _log_uniform(rng, *slip_range(generator)),
                    float(rng.uniform(lo, hi)))
    raise ValueError(f"unknown state {state!r}")


def place_path(motion: Motion, rng: np.random.Generator, size: tuple[int, int],
               mm_per_px: float) -> tuple[float, float]:
    """A start centre (px) so that the whole path stays in the central part of the frame."""
    height, width = size
    start = []
    for extent, delta in ((width, motion.dx_mm / mm_per_px), (height, -motion.dy_mm / mm_per_px)):
        lo = BORDER_SHARE * (extent - 1) - min(0.0, delta)
        hi = (1.0 - BORDER_SHARE) * (extent - 1) - max(0.0, delta)
        start.append(float(rng.uniform(lo, hi)) if hi > lo else (extent - 1 - delta) / 2.0)
    return start[0], start[1]


def sequence_scene(obj: ObjectInstance, motion: Motion, start_px: tuple[float, float],
                   n_frames: int, size: tuple[int, int], mm_per_px: float,
                   effects: Effects | None = None) -> Scene:
    """The scene of a sequence; its effects say motion only if the object moves."""
    centers = motion.centers(start_px, n_frames, mm_per_px)
    if effects is None:
        effects = Effects(texture=obj.cls.texture is not None, motion=len(set(centers)) > 1)
    return Scene(obj, centers, motion.depths(n_frames), size, mm_per_px, effects)
