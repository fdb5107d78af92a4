"""A scene (object, pose per frame, effects it needs) and the renderer that computes only those.

The renderer evaluates the object's height field on the object's footprint box, its
micro-texture only where the object can reach the gel, solves the gel on the overlap box plus
the spread margin, and shades only that box, pasting it onto the cached flat image; everything
outside the box is the flat image plus noise. A scene without motion evaluates the geometry
once; frames whose pose and depth repeat reuse the gel solution and shading.
"""

from __future__ import annotations

import dataclasses
import math
from collections import Counter
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from . import gel
from .objects import ObjectInstance
from .optics import DEFAULT_LIGHTS, Capture, capture_frame, sensor

if TYPE_CHECKING:
    from .appearance import Appearance
    from .mechanics import ContactPath, Mechanics

#: How many times each stage ran (a spy for tests and benchmarks): geometry, texture, gel, shade.
COUNTS: Counter[str] = Counter()


@dataclass(frozen=True)
class Effects:
    """What a scene needs computed; the renderer computes nothing else."""

    texture: bool = True  # micro-texture on the object
    spread: bool = True  # gel spreading (skirt, bridging); off: the coating conforms finely only
    motion: bool = False  # the object moves between frames: evaluate the geometry every frame
    noise: bool = True  # read and shot noise
    vignetting: bool = True
    nonuniform_light: bool = True  # per-pixel LED direction and intensity
    crop: bool = True  # compute only inside the contact box (off: over the whole frame)

    @classmethod
    def everything(cls) -> Effects:
        """Every effect forced on and nothing cropped: the naive renderer, for comparison."""
        return cls(texture=True, spread=True, motion=True, noise=True, vignetting=True,
                   nonuniform_light=True, crop=False)


@dataclass(frozen=True, eq=False)
class Scene:
    """An object pressed into the gel, with its centre (px, y down) and depth (mm) per frame."""

    obj: ObjectInstance
    centers_px: tuple[tuple[float, float], ...]
    depths_mm: tuple[float, ...]
    size: tuple[int, int]  # (height, width)
    mm_per_px: float
    effects: Effects = Effects()
    #: Generator 2: gel constants of the contact mechanics (None: the gel has no shear).
    mechanics: Mechanics | None = None
    #: Generator 2: the sensor's fixed gel pattern and camera (None: none of them).
    appearance: Appearance | None = None
    #: Generator 2: rotation, gel shear and stick region per frame (None: a rigid shift).
    path: ContactPath | None = None
    #: The sensor's light layout (a name of `optics.LIGHTS`).
    lights: str = DEFAULT_LIGHTS

    def __post_init__(self) -> None:
        """Refuse inconsistent scenes: one centre and depth per frame, motion declared."""
        if len(self.centers_px) != len(self.depths_mm) or not self.centers_px:
            raise ValueError("a scene needs one centre and one depth per frame")
        if not self.effects.motion and len(set(self.centers_px)) > 1:
            raise ValueError("the object moves but the scene's effects say no motion")
        if self.path is not None:
            if len(self.path.rotations_deg) != self.n_frames or len(self.path.stick) != \
                    self.n_frames:
                raise ValueError("a contact path needs one rotation and stick ratio per frame")
            if not self.effects.motion and len(set(self.path.rotations_deg)) > 1:
                raise ValueError("the object rotates but the scene's effects say no motion")

    @property
    def n_frames(self) -> int:
        """Number of frames."""
        return len(self.depths_mm)

    def with_effects(self, effects: Effects) -> Scene:
        """The same scene with other effects (e.g. Effects.everything())."""
        return dataclasses.replace(self, effects=effects)


@dataclass
class Rendered:
    """Frames and exact ground truth of a scene."""

    frames: np.ndarray  # (T, H, W, 3) uint8 RGB
    depth_mm: np.ndarray  # (T, H, W) float32, indentation into the gel
    grad: np.ndarray  # (T, H, W, 2) float32, (dD/dx, dD/dy) with y down the rows
    contact: np.ndarray  # (T, H, W) bool
    motion_px: np.ndarray  # (T, 2) float32, object displacement from frame 0 (x right, y down)
    #: (T, H, W, 2) float32: the gel surface's tangential displacement from frame 0 in px (x
    #: right, y down), or None where the surface does not move (no contact path).
    surface_px: np.ndarray | None = None


@dataclass
class _Geometry:
    """Height field (mm, float64) of the object over a box of absolute pixel rows/cols."""

    y0: int
    x0: int
    height: np.ndarray | None  # None: the object reaches nowhere near the frame


@dataclass
class _Shaded:
    """Truth and shaded patch of one pose, over the frame region rows x cols."""

    rows: slice
    cols: slice
    depth: np.ndarray | None  # float64
    gx: np.ndarray | None
    gy: np.ndarray | None
    contact: np.ndarray | None
    patch: np.ndarray | None  # float32 (h, w, 3)


def _align_down(a: int, f: int) -> int:
    """Largest multiple of f not above a."""
    return (a // f) * f


def _align_up(a: int, f: int) -> int:
    """Smallest multiple of f not below a."""
    return -((-a) // f) * f


def _geometry(scene: Scene, center: tuple[float, float], reach_mm: float,
              obj: ObjectInstance | None = None) -> _Geometry:
    """Evaluate the object (shape, and texture where it can reach depth reach_mm) on its box;
    obj, when given, is the scene's object in another pose (rotated)."""
    obj = scene.obj if obj is None else obj
    h_px, w_px = scene.size
    eff = scene.effects
    mpp = scene.mm_per_px
    margin = gel.margin_px(mpp, eff.spread)
    cx, cy = center
    if eff.crop:
        r = obj.radius_mm / mpp + 1.0
        x0, x1 = max(math.floor(cx - r), -margin), min(math.ceil(cx + r) + 1, w_px + margin)
        y0, y1 = max(math.floor(cy - r), -margin), min(math.ceil(cy + r) + 1, h_px + margin)
    else:
        f = gel.spread_factor(mpp) if eff.spread else 1
        x0, x1 = _align_down(-margin, f), _align_up(w_px + margin, f)
        y0, y1 = _align_down(-margin, f), _align_up(h_px + margin, f)
    if x1 <= x0 or y1 <= y0:
        return _Geometry(0, 0, None)
    COUNTS["geometry"] += 1
    xs = (np.arange(x0, x1, dtype=np.float64) - cx) * mpp
    ys = (np.arange(y0, y1, dtype=np.float64) - cy) * mpp
    u, v = obj.local(xs[None, :], ys[:, None])
    height = obj.shape(u, v)
    bound = obj.texture_bound_mm
    if eff.texture and obj.cls.texture is not None:
        if eff.crop:  # texture only where shape + texture can rise above -reach
            reach = height > -reach_mm - bound
            rows = np.flatnonzero(reach.any(axis=1))
            cols = np.flatnonzero(reach.any(axis=0))
            sub = (slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1)) if rows.size \
                else None
        else:
            sub = (slice(None), slice(None))
        if sub is not None:
            COUNTS["texture"] += 1
            height[sub] += obj.texture(u[sub], v[sub])
    return _Geometry(y0, x0, height)


def _solve(scene: Scene, geom: _Geometry, depth_mm: float, sensor_fields) -> _Shaded:
    """Gel indentation, gradients, contact and shading of one pose (one depth)."""
    h_px, w_px = scene.size
    eff = scene.effects
    mpp = scene.mm_per_px
    none = _Shaded(slice(0, 0), slice(0, 0), None, None, None, None, None)
    if geom.height is None:
        return none
    overlap = geom.height + depth_mm
    np.maximum(overlap, 0.0, out=overlap)
    f = gel.spread_factor(mpp) if eff.spread else 1
    if eff.crop:
        pos = overlap > 0.0
        rows = np.flatnonzero(pos.any(axis=1))
        if not rows.size:
            return none
        cols = np.flatnonzero(pos.any(axis=0))
        margin = gel.margin_px(mpp, eff.spread)
        gy0 = _align_down(geom.y0 + int(rows[0]) - margin, f)
        gy1 = _align_up(geom.y0 + int(rows[-1]) + 1 + margin, f)
        gx0 = _align_down(geom.x0 + int(cols[0]) - margin, f)
        gx1 = _align_up(geom.x0 + int(cols[-1]) + 1 + margin, f)
        box = np.zeros((gy1 - gy0, gx1 - gx0))
        oy0, ox0 = max(gy0, geom.y0), max(gx0, geom.x0)
        oy1 = min(gy1, geom.y0 + overlap.shape[0])
        ox1 = min(gx1, geom.x0 + overlap.shape[1])
        box[oy0 - gy0:oy1 - gy0, ox0 - gx0:ox1 - gx0] = \
            overlap[oy0 - geom.y0:oy1 - geom.y0, ox0 - geom.x0:ox1 - geom.x0]
    else:
        gy0, gx0 = geom.y0, geom.x0
        gy1, gx1 = gy0 + overlap.shape[0], gx0 + overlap.shape[1]
        box = overlap
    COUNTS["gel"] += 1
    depth, contact = gel.solve(box, mpp, eff.spread)
    # Frame region: the gel box inside the frame, grown by 2 px so that the central differences
    # at its edge see only zeros (the gradient then equals that of the whole frame).
    fy0, fy1 = max(gy0, 0), min(gy1, h_px)
    fx0, fx1 = max(gx0, 0), min(gx1, w_px)
    if fy1 <= fy0 or fx1 <= fx0:
        return none
    if eff.crop:
        ry0, ry1 = max(fy0 - 2, 0), min(fy1 + 2, h_px)
        rx0, rx1 = max(fx0 - 2, 0), min(fx1 + 2, w_px)
    else:
        ry0, ry1, rx0, rx1 = 0, h_px, 0, w_px
    d = np.zeros((ry1 - ry0, rx1 - rx0))
    c = np.zeros(d.shape, bool)
    src = (slice(fy0 - gy0, fy1 - gy0), slice(fx0 - gx0, fx1 - gx0))
    dst = (slice(fy0 - ry0, fy1 - ry0), slice(fx0 - rx0, fx1 - rx0))
    d[dst] = depth[src]
    c[dst] = contact[src]
    gy, gx = np.gradient(d, mpp)
    rows, cols = slice(ry0, ry1), slice(rx0, rx1)
    COUNTS["shade"] += 1
    patch = sensor_fields.shade(gx, gy, rows, cols)
    return _Shaded(rows, cols, d, gx, gy, c, patch)


def _pivot(scene: Scene, depth_mm: float) -> tuple[float, float]:
    """Contact centre (px) of the first pose at depth_mm: centroid of the rigid overlap (the
    object's centre when it touches nothing); rotations of the contact path turn about it."""
    geom = _geometry(scene, scene.centers_px[0], depth_mm)
    if geom.height is None:
        return scene.centers_px[0]
    ys, xs = np.nonzero(geom.height + depth_mm > 0.0)
    if not xs.size:
        return scene.centers_px[0]
    return float(xs.mean()) + geom.x0, float(ys.mean()) + geom.y0


def _posed(scene: Scene, t: int, pivot: tuple[float, float]) -> tuple[tuple[float, float],
                                                                       ObjectInstance]:
    """Object centre (px) and instance of frame t: frame 0's pose turned by the path's rotation
    about the pivot (counter-clockwise in the image), then shifted by the frame's translation."""
    assert scene.path is not None
    theta = scene.path.rotations_deg[t]
    (cx, cy), (x0, y0) = scene.centers_px[t], scene.centers_px[0]
    if theta == 0.0:
        return (cx, cy), scene.obj
    a = math.radians(theta)
    ox, oy = x0 - pivot[0], y0 - pivot[1]
    # counter-clockwise on screen with y down the rows: (x, y) -> (cos x + sin y, -sin x + cos y)
    rx, ry = math.cos(a) * ox + math.sin(a) * oy, -math.sin(a) * ox + math.cos(a) * oy
    center = (cx - x0 + pivot[0] + rx, cy - y0 + pivot[1] + ry)
    return center, dataclasses.replace(scene.obj, rotation_deg=scene.obj.rotation_deg - theta)


def render(scene: Scene, capture: Capture | None = None,
           rng: np.random.Generator | None = None) -> Rendered:
    """Render a scene's frames (noise from rng; default camera settings) and its exact truth."""
    capture = Capture() if capture is None else capture
    eff = scene.effects
    if eff.noise and rng is None:
        raise ValueError("a scene with noise needs an rng")
    h_px, w_px = scene.size
    t_n = scene.n_frames
    fields = sensor(h_px, w_px, scene.mm_per_px, eff.vignetting, eff.nonuniform_light,
                    scene.lights)
    frames = np.empty((t_n, h_px, w_px, 3), np.uint8)
    depth = np.zeros((t_n, h_px, w_px), np.float32)
    grad = np.zeros((t_n, h_px, w_px, 2), np.float32)
    contact = np.zeros((t_n, h_px, w_px), bool)
    c0 = scene.centers_px[0]
    motion = np.array([(c[0] - c0[0], c[1] - c0[1]) for c in scene.centers_px], np.float32)
    geom: _Geometry | None = None
    shaded: _Shaded | None = None
    last: tuple | None = None
    deepest = max(scene.depths_mm)
    shots: list[tuple[np.ndarray | None, slice, slice]] = []
    pivot = _pivot(scene, deepest) if scene.path is not None else c0
    for t in range(t_n):
        center, d = scene.centers_px[t], scene.depths_mm[t]
        if eff.motion or geom is None:
            obj = None
            if scene.path is not None:
                center, obj = _posed(scene, t, pivot)
            geom = _geometry(scene, center, d if eff.motion else deepest, obj)
        if eff.motion or (center, d) != last:
            shaded = _solve(scene, geom, d, fields)
            last = (center, d)
        assert shaded is not None
        if shaded.depth is not None:
            r, c = shaded.rows, shaded.cols
            depth[t, r, c] = shaded.depth
            grad[t, r, c, 0] = shaded.gx
            grad[t, r, c, 1] = shaded.gy
            contact[t, r, c] = shaded.contact
        if scene.appearance is None:
            frames[t] = capture_frame(fields, capture, rng if eff.noise else None,
                                      shaded.patch, shaded.rows, shaded.cols)
        else:  # captured below, through the sensor's gel pattern and camera
            shots.append((shaded.patch, shaded.rows, shaded.cols))
    surface = rest = None
    if scene.path is not None and scene.mechanics is not None:
        from .mechanics import surface_displacement

        # from the unloaded gel (the pattern of a preloaded first frame is already displaced
        # against the session's background); the truth is from frame 0
        rest = surface_displacement(contact, motion, pivot, scene.path, scene.mechanics,
                                    scene.mm_per_px, from_rest=True)
        surface = rest - rest[0] if rest[0].any() else rest
    if scene.appearance is not None:
        from .appearance import capture as appearance_capture

        frames = appearance_capture(scene.appearance, fields, capture,
                                    rng if eff.noise else None, shots, rest)
    return Rendered(frames, depth, grad, contact, motion, surface)
