"""Relighting: a rendered scene's exact surface gradients shot again through another sensor (any
light layout of `optics`), with the gel's pattern and camera of generator 2 when asked; what the
simulated press variants of a calibration benchmark are made of."""

from __future__ import annotations

import numpy as np

from .appearance import Appearance
from .appearance import capture as appearance_capture
from .optics import Capture, Sensor, capture_frame


def relight(grad: np.ndarray, fields: Sensor, capture: Capture | None = None,
            rng: np.random.Generator | None = None,
            appearance: Appearance | None = None) -> np.ndarray:
    """Camera frames (T, H, W, 3) uint8 of the exact surface gradients `grad` (T, H, W, 2),
    (dD/dx, dD/dy) with y down the rows (a rendered scene's truth), shot through `fields` (a
    sensor of any light layout) as `scene.render` shoots them: the box where the surface is bent
    (grown by 2 px) shaded, the flat image elsewhere, noise from rng (None: none), and through
    the gel pattern and camera of `appearance` when given."""
    capture = Capture() if capture is None else capture
    h, w = fields.height, fields.width
    shots: list[tuple[np.ndarray | None, slice, slice]] = []
    for g in grad:
        bent = np.any(g != 0.0, axis=-1)
        ys, xs = np.flatnonzero(bent.any(axis=1)), np.flatnonzero(bent.any(axis=0))
        if not ys.size:
            shots.append((None, slice(0, 0), slice(0, 0)))
            continue
        rows = slice(max(int(ys[0]) - 2, 0), min(int(ys[-1]) + 3, h))
        cols = slice(max(int(xs[0]) - 2, 0), min(int(xs[-1]) + 3, w))
        shots.append((fields.shade(g[rows, cols, 0], g[rows, cols, 1], rows, cols), rows, cols))
    if appearance is None:
        return np.stack([capture_frame(fields, capture, rng, p, r, c) for p, r, c in shots])
    return appearance_capture(appearance, fields, capture, rng, shots, None)
