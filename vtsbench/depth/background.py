"""The no-contact frame: estimated from the press frames themselves for sets recorded without
one, where that estimate cannot be trusted, and a given one that shows a contact of its own.

The per-pixel median of the presses is the gel untouched wherever fewer than half of them touch
it. Where half or more do (a stage pressing the centre at several depths), the median there is a
press, and every press there is measured against a press: on 16 simulated presses within 40 px
of the centre (a 60 px ball, contacts of 17-43 px) held-out depth was 2.3 times the error with
the true background (0.0191 against 0.0084 mm), with nothing said. `crowded` finds such a spot
so that calibration can say so. Taking each press's own contact, grown to twice its radius, out
of the median (per pixel, the frames that leave it free) was tried and not kept: where every
press touches there is no frame to take, and it did no better (0.0215 mm; within 70 px of the
centre, where the plain median holds, 0.0113 against 0.0109 mm, the true background 0.0115).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

#: The plain median fails where at least this share of the presses touch one pixel (its
#: breakdown point).
CROWDED_SHARE = 0.5


#: Rows per block of the median: the stack and the sorted copy the median makes stay small (40
#: frames of 1920x1440 take 15 MB a block, not 2 x 330 MB at once), and it is quicker (20 such
#: frames: 2.32 s against 3.50 s for the whole stack, 2-core AMD EPYC).
_BLOCK_ROWS = 32


def press_median(frames: Sequence[np.ndarray]) -> np.ndarray:
    """The per-pixel median of the press frames (uint8 H x W x 3), a block of rows at a time."""
    out = np.empty(frames[0].shape, np.uint8)
    for r0 in range(0, out.shape[0], _BLOCK_ROWS):
        rows = slice(r0, r0 + _BLOCK_ROWS)
        out[rows] = np.median(np.stack([f[rows] for f in frames]), axis=0).round()
    return out


def _disc_box(x: float, y: float, r: float, shape: tuple[int, int]
              ) -> tuple[tuple[slice, slice], np.ndarray] | None:
    """The box (rows, columns) around a disc (x, y, r px) clipped to a frame of `shape`, and the
    disc's pixels in it (bool); None when none of it lies in the frame."""
    h, w = shape
    x0, x1 = max(0, math.floor(x - r)), min(w, math.ceil(x + r) + 1)
    y0, y1 = max(0, math.floor(y - r)), min(h, math.ceil(y + r) + 1)
    if x0 >= x1 or y0 >= y1:
        return None
    yy, xx = np.ogrid[y0:y1, x0:x1]
    mask = (xx - x) ** 2 + (yy - y) ** 2 <= r * r
    return ((slice(y0, y1), slice(x0, x1)), mask) if mask.any() else None


def crowded(shape: tuple[int, int], circles: Sequence[tuple[float, float, float]],
            n_frames: int) -> tuple[int, tuple[int, int]] | None:
    """(presses, (x, y) px): how many contact circles (x, y, r px) overlap most and the middle of
    where they do, when they are at least CROWDED_SHARE of the n_frames the median was taken
    over; None otherwise."""
    if not circles or n_frames <= 0:
        return None
    count = np.zeros(shape, np.int32)
    for x, y, r in circles:
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(r)):
            continue
        found = _disc_box(x, y, r, shape)
        if found is not None:
            count[found[0]] += found[1]
    top = int(count.max())
    if top < CROWDED_SHARE * n_frames:
        return None
    ys, xs = np.nonzero(count == top)  # the middle of where the most overlap
    return top, (round(float(xs.mean())), round(float(ys.mean())))


#: A given background shows a contact of its own (a press frame passed as the background) when
#: the presses agree there as they do on the rest of the gel: their typical departure from their
#: median inside its circle is below OWN_CONTACT_SPREAD times their typical departure over the
#: frame (the noise). Measured: 1.00-1.33 with a press frame as the background, of the real sets
#: (Taxim 010 and 030; DIGIT 0003, 0010 and 0016, taken under another light) and of simulated
#: ones (three light layouts, a shallow press of 14 px among them); 2.8 and 4.3 with the true
#: background of 8 and 16 simulated presses all within 8-10 px of the centre, where the median
#: is a press and the presses differ from it, each in its own place and depth.
OWN_CONTACT_SPREAD = 2.0
#: Fewer press frames give no median to hold a background against.
MIN_FRAMES = 5


def own_contact(background: np.ndarray, frames: Sequence[np.ndarray], ball_px: float,
                med: np.ndarray | None = None) -> tuple[float, float, float] | None:
    """The contact circle (x, y, r px) that a given background shows against the presses'
    median (`med`, when the caller has it) and the presses do not (see OWN_CONTACT_SPREAD; a
    noise below 1 DN counts as 1), or None."""
    if len(frames) < MIN_FRAMES:
        return None
    from .imprint import ring_contrast
    from .sphere import RING_Z_MIN, change_map, circle_doubts, default_sigma, detect_circle

    med = press_median(frames) if med is None else med
    c = detect_circle(background, med, ball_px=ball_px, restarts=False)
    if c is None:
        return None
    m = change_map(background, med, default_sigma(background.shape[:2]), markers=True)
    if ring_contrast(m, c) < RING_Z_MIN or circle_doubts(c, background, med, ball_px, m):
        return None
    found = _disc_box(c[0], c[1], 0.8 * c[2], m.shape)
    if found is None:
        return None
    box, disc = found
    ref = med[box].astype(np.float32)
    inside = float(np.median(np.median(np.stack(
        [np.abs(f[box] - ref).sum(-1)[disc] for f in frames]), axis=0)))
    grid = med[::4, ::4].astype(np.float32)  # the noise, on every 4th pixel (bounded memory)
    noise = float(np.median(np.median(np.stack(
        [np.abs(f[::4, ::4] - grid).sum(-1) for f in frames]), axis=0)))
    return c if inside < OWN_CONTACT_SPREAD * max(noise, 1.0) else None


#: A given background whose colour channels come in the other order than the presses' (a BGR
#: file where RGB was meant, or the other way): reversed, it lies at most SWAP_GAIN times as far
#: from the presses' median as it does as given, and as given at least SWAP_MIN_DN (the median
#: over pixels of the difference summed over channels). Measured: Taxim's background reversed,
#: 44 DN as given and 15 reversed (its own background: 15 and 44, the light having drifted);
#: simulated backgrounds 2-3 DN as given, 6-52 reversed.
SWAP_GAIN, SWAP_MIN_DN = 0.5, 6.0


def channels_reversed(background: np.ndarray, med: np.ndarray) -> tuple[float, float] | None:
    """(as given, reversed): how far the background lies from the presses' median `med` as
    given and with its channels reversed (DN, see SWAP_GAIN), when reversed fits them; None
    otherwise."""
    b, m = background.astype(np.float32), med.astype(np.float32)
    given = float(np.median(np.abs(b - m).sum(-1)))
    rev = float(np.median(np.abs(b[..., ::-1] - m).sum(-1)))
    return (given, rev) if given >= SWAP_MIN_DN and rev <= SWAP_GAIN * given else None
