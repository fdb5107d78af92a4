"""The gel's fixed pattern: printed markers, dust and scratches on the surface, the border band.

The pattern is a transmission layer (1 = clear, 0 = black) that multiplies the image. Markers,
dust and scratches sit on the gel surface and ride its tangential displacement; the border band
belongs to the sensor's frame and never moves. A gel's pattern is drawn once from
(pattern_seed, gel) and cached, so every frame and every session background of that gel shows
the same pattern.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .appearance import Appearance

#: Displacements below this (px) leave the pattern where it is (no warp computed).
STILL_PX = 0.01


@dataclass(frozen=True, eq=False)
class GelPattern:
    """One gel's layers over a frame: `surface` rides the gel, `border` is fixed."""

    surface: np.ndarray  # (H, W) float32 transmission of markers, dust and scratches
    border: np.ndarray  # (H, W) float32 transmission of the frame's edge band
    still: np.ndarray  # (H, W) float32, surface * border: the layer of an undisplaced gel
    markers: bool


def has_markers(app: Appearance, gel: int) -> bool:
    """Whether gel number `gel` has a printed marker grid: a share `marker_share` of gels,
    spread evenly over consecutive gel numbers (0.5: every other gel)."""
    if app.marker_share <= 0.0:
        return False
    if app.marker_share >= 1.0:
        return True
    phase = np.random.default_rng([app.pattern_seed, 1]).random()
    return (gel * app.marker_share + phase) % 1.0 < app.marker_share


def _disc(layer: np.ndarray, x: float, y: float, radius: float, edge: float,
          depth: float) -> None:
    """Darken `layer` by a soft disc (centre x, y px; linear edge `edge` px wide) in place."""
    h, w = layer.shape
    reach = radius + edge
    x0, x1 = max(math.floor(x - reach), 0), min(math.ceil(x + reach) + 1, w)
    y0, y1 = max(math.floor(y - reach), 0), min(math.ceil(y + reach) + 1, h)
    if x1 <= x0 or y1 <= y0:
        return
    xs = np.arange(x0, x1, dtype=np.float32) - np.float32(x)
    ys = np.arange(y0, y1, dtype=np.float32)[:, None] - np.float32(y)
    r = np.sqrt(xs * xs + ys * ys)
    cover = np.clip((radius - r) / max(edge, 1e-3) + 0.5, 0.0, 1.0)
    layer[y0:y1, x0:x1] *= 1.0 - np.float32(depth) * cover


def _segment(layer: np.ndarray, p: tuple[float, float], q: tuple[float, float], width: float,
             depth: float) -> None:
    """Darken `layer` along the segment p-q (px), `width` px wide with 1 px soft edges."""
    h, w = layer.shape
    reach = width / 2 + 1.0
    x0 = max(math.floor(min(p[0], q[0]) - reach), 0)
    x1 = min(math.ceil(max(p[0], q[0]) + reach) + 1, w)
    y0 = max(math.floor(min(p[1], q[1]) - reach), 0)
    y1 = min(math.ceil(max(p[1], q[1]) + reach) + 1, h)
    if x1 <= x0 or y1 <= y0:
        return
    xs = np.arange(x0, x1, dtype=np.float64)[None, :]
    ys = np.arange(y0, y1, dtype=np.float64)[:, None]
    dx, dy = q[0] - p[0], q[1] - p[1]
    s = np.clip(((xs - p[0]) * dx + (ys - p[1]) * dy) / max(dx * dx + dy * dy, 1e-9), 0.0, 1.0)
    r = np.hypot(xs - p[0] - s * dx, ys - p[1] - s * dy)
    cover = np.clip(width / 2 - r + 0.5, 0.0, 1.0)
    layer[y0:y1, x0:x1] *= (1.0 - depth * cover).astype(np.float32)


def _markers(layer: np.ndarray, app: Appearance, rng: np.random.Generator,
             mm_per_px: float) -> None:
    """A printed grid of dark dots, slightly turned, with small print jitter."""
    h, w = layer.shape
    pitch = app.marker_pitch_mm / mm_per_px
    radius = app.marker_diameter_mm / 2 / mm_per_px
    angle = math.radians(float(rng.uniform(-1.0, 1.0)))
    ca, sa = math.cos(angle), math.sin(angle)
    ox, oy = rng.uniform(0.0, pitch, 2)
    n = math.ceil(math.hypot(h, w) / pitch) + 2
    cx, cy = (w - 1) / 2, (h - 1) / 2
    for i in range(-n, n + 1):
        for j in range(-n, n + 1):
            u, v = i * pitch + ox, j * pitch + oy
            x = cx + ca * u - sa * v
            y = cy + sa * u + ca * v
            if -pitch < x < w + pitch and -pitch < y < h + pitch:
                jx, jy = rng.normal(0.0, app.marker_jitter_mm / mm_per_px, 2)
                r = radius * float(rng.uniform(0.95, 1.05))
                _disc(layer, x + jx, y + jy, r, app.marker_edge_mm / mm_per_px,
                      app.marker_darkness)


def _dust(layer: np.ndarray, app: Appearance, rng: np.random.Generator,
          mm_per_px: float) -> None:
    """Dust specks (Poisson count per area) and a few short scratches."""
    h, w = layer.shape
    area_cm2 = h * w * (mm_per_px / 10.0) ** 2
    lo, hi = app.dust_diameter_mm
    for _ in range(int(rng.poisson(app.dust_per_cm2 * area_cm2))):
        d = math.exp(rng.uniform(math.log(lo), math.log(hi))) / mm_per_px
        x, y = rng.uniform(0, w - 1), rng.uniform(0, h - 1)
        _disc(layer, x, y, d / 2, 1.0, float(rng.uniform(*app.dust_darkness)))
    for _ in range(int(rng.integers(0, app.scratches + 1))):
        length = rng.uniform(*app.scratch_length_mm) / mm_per_px
        a = rng.uniform(0.0, math.pi)
        x, y = rng.uniform(0, w - 1), rng.uniform(0, h - 1)
        p = (x - length / 2 * math.cos(a), y - length / 2 * math.sin(a))
        q = (x + length / 2 * math.cos(a), y + length / 2 * math.sin(a))
        _segment(layer, p, q, app.scratch_width_mm / mm_per_px,
                 float(rng.uniform(*app.dust_darkness)))


def _border(h: int, w: int, app: Appearance, rng: np.random.Generator,
            mm_per_px: float) -> np.ndarray:
    """The frame's edge band: full darkness over `border_mm`, then a linear ramp to clear."""
    band = app.border_mm / mm_per_px
    ramp = max(app.border_ramp_mm / mm_per_px, 1e-3)
    dist = {"left": np.arange(w, dtype=np.float32)[None, :],
            "right": (w - 1 - np.arange(w, dtype=np.float32))[None, :],
            "top": np.arange(h, dtype=np.float32)[:, None],
            "bottom": (h - 1 - np.arange(h, dtype=np.float32))[:, None]}
    out = np.ones((h, w), np.float32)
    for side in ("left", "right", "top", "bottom"):
        depth = np.float32(rng.uniform(*app.border_darkness))
        cover = np.clip(1.0 - (dist[side] - band) / ramp, 0.0, 1.0)
        out *= 1.0 - depth * cover
    return out


@lru_cache(maxsize=8)
def gel_pattern(app: Appearance, gel: int, height: int, width: int,
                mm_per_px: float) -> GelPattern:
    """The fixed pattern of gel number `gel` at a frame size and scale (cached per process)."""
    rng = np.random.default_rng([app.pattern_seed, 2, gel])
    markers = has_markers(app, gel)
    surface = np.ones((height, width), np.float32)
    border = _border(height, width, app, rng, mm_per_px)
    if markers:
        _markers(surface, app, rng, mm_per_px)
    _dust(surface, app, rng, mm_per_px)
    if app.grain > 0.0:  # the coating's fine grain: a fixed texture of every spatial frequency
        surface *= 1.0 + np.float32(app.grain) * rng.standard_normal((height, width),
                                                                      np.float32)
    return GelPattern(surface, border, surface * border, markers)


def layer_at(pattern: GelPattern,
             shift: np.ndarray | None) -> tuple[np.ndarray, tuple[slice, slice] | None]:
    """The transmission (H, W) float32 of a frame whose gel surface moved by `shift`
    ((H, W, 2) px, x right, y down, from frame 0; None = not moved), and the box where it
    differs from `pattern.still` (None: nowhere). The surface layer is pulled back along the
    displacement (cv2.remap) where that exceeds STILL_PX."""
    if shift is None:
        return pattern.still, None
    h, w = shift.shape[:2]
    flat = shift.reshape(h, w * 2)  # reductions along the contiguous axis are fast
    rows = np.flatnonzero((flat.max(axis=1) > STILL_PX) | (flat.min(axis=1) < -STILL_PX))
    if not rows.size:
        return pattern.still, None
    import cv2

    r0, r1 = int(rows[0]), int(rows[-1]) + 1
    band = flat[r0:r1]
    cols = np.flatnonzero(((band.max(axis=0) > STILL_PX) | (band.min(axis=0) < -STILL_PX))
                          .reshape(w, 2).any(axis=1))
    c0, c1 = int(cols[0]), int(cols[-1]) + 1
    sub = shift[r0:r1, c0:c1].astype(np.float32)
    map_x = np.arange(c0, c1, dtype=np.float32)[None, :] - sub[..., 0]
    map_y = np.arange(r0, r1, dtype=np.float32)[:, None] - sub[..., 1]
    warped = cv2.remap(pattern.surface, map_x, map_y, cv2.INTER_LINEAR,
                       borderMode=cv2.BORDER_REFLECT)
    out = pattern.still.copy()
    out[r0:r1, c0:c1] = warped * pattern.border[r0:r1, c0:c1]
    return out, (slice(r0, r1), slice(c0, c1))
