"""Where and how far the gel moves over a sequence, by phase correlation: the motion window,
the displacement of each frame from the first, and that displacement drawn as a two-channel
field for models (the slip TimeSformer's motion channels, the flow recipe's direction).

Global registration, not dense flow: on elongated imprints (a ridge, a plug, a cylinder) a local
flow sees only the motion across an edge (the aperture problem), and its mean points across the
object; the phase correlation of the whole moving region is held by the object's ends. On the
demo's slipping sequences (unseen_objects, 75 train / 37 test), the angle of the mean DIS flow
(medium preset, first to last frame, windowed) bins right 88 / 57 % at a 256 px crop and
87 / 68 % at 480 px; the phase correlation of the same frames 96 / 84 % and 97 / 97 %.
"""

from __future__ import annotations

import numpy as np


def motion_window(gray: list[np.ndarray], level: float = 4.0, sigma: float = 3.0
                  ) -> np.ndarray | None:
    """Where the gel moves: a smooth window (float32, peak 1) over the pixels whose grey level
    changes by more than `level` against the first frame at some time (blurred by `sigma` px,
    dilated by a quarter of the moving region's size), times a Hanning window against edge
    effects. None when nothing moves."""
    import cv2

    g = np.stack(gray).astype(np.float32)
    change = cv2.GaussianBlur(np.abs(g[1:] - g[:1]).max(axis=0), (0, 0), sigma)
    mask = (change > level).astype(np.float32)
    if not mask.any():
        return None
    ys, xs = np.nonzero(mask)
    k = max(3, int(0.25 * max(np.ptp(xs), np.ptp(ys))) | 1)
    mask = cv2.dilate(mask, np.ones((k, k), np.uint8))
    mask = cv2.GaussianBlur(mask, (0, 0), max(1.0, k / 4))
    h, w = mask.shape
    return (mask * cv2.createHanningWindow((w, h), cv2.CV_32F)).astype(np.float32)


#: The global shift is measured on frames no smaller than this (shorter side, px): phase
#: correlation of a small frame shrunk further has too few pixels to find the peak.
MIN_SHIFT_SIDE = 240


def shift_scale(shape: tuple[int, int], scale: float) -> float:
    """The resize factor the global shift uses: `scale`, raised so that the shorter side keeps
    MIN_SHIFT_SIDE pixels, and never above 1."""
    return float(min(1.0, max(scale, MIN_SHIFT_SIDE / max(1, min(shape)))))


def frame_shifts(gray: list[np.ndarray], window: np.ndarray | None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The displacement (x right, y down the rows, pixels of the input) of each float32 grey
    frame from the first, by phase correlation inside `window`: (T, 2) float64 shifts (row 0
    and every row of a sequence where nothing moves, `window` None, are 0) and the (T - 1,)
    correlation peaks of the later frames (0 where nothing moves)."""
    import cv2

    shifts = np.zeros((len(gray), 2))
    peaks = np.zeros(max(0, len(gray) - 1))
    if window is None:
        return shifts, peaks
    for t in range(1, len(gray)):
        # OpenCV's phaseCorrelate applies the window to its inputs in place (OpenCV 5.0, at
        # sizes its DFT takes as they are): copies, or frame 0 would be windowed t times
        (sx, sy), peaks[t - 1] = cv2.phaseCorrelate(gray[0].copy(), gray[t].copy(), window)
        shifts[t] = sx, sy
    return shifts, peaks


def shift_field(grey: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """(T, 2, H, W) float32 for a (T, H, W) uint8 grey sequence: each frame's displacement from
    the first (`frame_shifts` on the whole frame at `scale`, raised by `shift_scale`), in
    sensor pixels, drawn over the motion window (weights in [0, 1]) and 0 where the gel is
    still. Cut and resized like the frames, it tells a model where the gel moves and which
    way, without the aperture problem of a local flow."""
    import cv2

    h, w = grey.shape[1:3]
    s = shift_scale((h, w), scale)
    gray = []
    for g in grey:
        if s != 1.0:
            g = cv2.resize(g, None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
        gray.append(g.astype(np.float32))
    win = motion_window(gray) if len(gray) > 1 else None
    out = np.zeros((len(grey), 2, h, w), np.float32)
    if win is None:
        return out
    shifts = frame_shifts(gray, win)[0].astype(np.float32) / s
    full = cv2.resize(win, (w, h), interpolation=cv2.INTER_LINEAR)
    full /= max(float(full.max()), 1e-6)
    out[:] = shifts[:, :, None, None] * full[None, None]
    return out
