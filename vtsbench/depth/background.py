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


def _distance(a: np.ndarray, b: np.ndarray, step: int = 4) -> float:
    """The median over pixels of |a - b| summed over channels (DN), on every `step`th pixel."""
    return float(np.median(np.abs(a[::step, ::step].astype(np.int16) - b[::step, ::step])
                           .sum(-1)))


def channels_reversed(background: np.ndarray, med: np.ndarray) -> tuple[float, float] | None:
    """(as given, reversed): how far the background lies from the presses' median `med` as
    given and with its channels reversed (DN, see SWAP_GAIN), when reversed fits them; None
    otherwise."""
    given, rev = _distance(background, med, 1), _distance(background[..., ::-1], med, 1)
    return (given, rev) if given >= SWAP_MIN_DN and rev <= SWAP_GAIN * given else None


#: Presses under another light than the background: those that lie at least LIGHT_OUTLIER times
#: as far from it as the nearest quarter of the presses do (the median over the frame of the
#: difference summed over channels; DIGIT 0016 and 0017: 51-52 DN from the presses' median, the
#: other 14 at 6-8; Taxim's 49 presses at 11-27 DN from their background, whose light drifted).
LIGHT_OUTLIER = 2.0
#: Such a press is held against other presses instead of the background when they lie at most
#: LIGHT_MATE_RATIO times as far from it as the background does (DIGIT 0016 and 0017 from each
#: other: 0.2 times).
LIGHT_MATE_RATIO = 0.5
#: A mate's own contact counts for nothing within MATE_GROW[0] times its radius and fully beyond
#: MATE_GROW[1] times, rising smoothly between (a hard edge would leave a ring where the mates'
#: mix changes, and a ring is what the detector looks for).
MATE_GROW = (1.2, 1.6)
#: The nearest mates that make a press's background (bounded memory and time).
MAX_MATES = 8


def light_mates(frames: dict[str, np.ndarray], background: np.ndarray
                ) -> dict[str, list[str]]:
    """Presses taken under another light than the background, each with the presses that share
    its light (nearest first): those at least LIGHT_OUTLIER times as far from the background as
    the nearest quarter, and of those the ones at most LIGHT_MATE_RATIO times as far from each
    other as from the background. Only the far presses are compared pairwise."""
    to_bg = {k: _distance(f, background) for k, f in frames.items()}
    if len(to_bg) < 2:
        return {}
    quarter = float(np.percentile(list(to_bg.values()), 25))
    far = [k for k, d in to_bg.items() if d >= max(2.0, LIGHT_OUTLIER * quarter)]
    out = {}
    for k in far:
        near = sorted((_distance(frames[k], frames[j]), j) for j in far if j != k)
        mates = [j for d, j in near if d <= LIGHT_MATE_RATIO * to_bg[k]]
        if mates:
            out[k] = mates
    return out


def mates_background(frames: Sequence[np.ndarray],
                     circles: Sequence[tuple[float, float, float] | None],
                     background: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A background for a press from presses under its light, and where it is filled in (bool).

    Each mate's light relative to the background (the log of their ratio, which a change of
    light alone leaves smooth: the gel's own pattern and markers divide out) is averaged with
    weights that leave out its contact smoothly (MATE_GROW; a mate whose circle is None counts
    everywhere). With three mates or more, a mate that departs far from the others at a pixel
    (a contact whose circle is unknown) counts less there, smoothly (`_robust`). Where the
    mates' contact weights sum below 1 the average is completed by the nearest mates' light,
    a Gaussian-weighted mean as wide as needed to reach them; pixels where they sum below a
    half are reported as filled."""
    import cv2

    shape = frames[0].shape[:2]
    base = background.astype(np.float32) + 1.0
    yy, xx = np.mgrid[:shape[0], :shape[1]].astype(np.float32)
    lo, hi = MATE_GROW
    widest, gains, weights = 1.0, [], []
    for f, c in zip(frames[:MAX_MATES], circles[:MAX_MATES], strict=False):
        gains.append(np.log((f.astype(np.float32) + 1.0) / base))
        if c is None:
            weights.append(np.ones(shape, np.float32))
            continue
        x, y, r = c
        w = np.clip((np.sqrt((xx - x) ** 2 + (yy - y) ** 2) / max(r, 1.0) - lo) / (hi - lo),
                    0.0, 1.0)
        weights.append(w * w * (3 - 2 * w))  # smoothstep: no kink at either end
        widest = max(widest, hi * r)
    g, w = np.stack(gains), np.stack(weights)
    total = w.sum(0)
    if len(gains) >= 3:
        w = w * _robust(g, w)
    acc = (w[..., None] * g).sum(0)
    gain = acc / np.maximum(w.sum(0), 1e-6)[..., None]
    have = np.minimum(total, 1.0)
    if (have < 1.0).any():  # complete from around: the narrowest mean that reaches the pixel
        near = np.zeros_like(gain)
        left, sigma = have < 1.0, 2.0
        wsum = w.sum(0)
        while left.any():
            weight = cv2.GaussianBlur(wsum, (0, 0), sigma)
            take = left & (weight >= 0.05) if sigma < 2 * widest else left
            near[take] = cv2.GaussianBlur(acc, (0, 0), sigma)[take] / np.maximum(
                weight[take], 1e-6)[:, None]
            left &= ~take
            sigma *= 2
        gain = have[..., None] * gain + (1.0 - have[..., None]) * near
    ref = base * np.exp(gain) - 1.0
    return np.clip(ref, 0, 255).round().astype(np.uint8), total < 0.5


def _robust(g: np.ndarray, w: np.ndarray, rounds: int = 2) -> np.ndarray:
    """Per mate and pixel, a factor in (0, 1] that falls smoothly (1 / (1 + (d / tau)^2)) as the
    mate departs from the mates' weighted mean there by d (summed over channels); tau is 3
    times the typical departure over the frame, so noise and texture keep their weight and a
    contact loses it."""
    k = np.ones_like(w)
    for _ in range(rounds):
        ww = w * k
        mean = (ww[..., None] * g).sum(0) / np.maximum(ww.sum(0), 1e-6)[..., None]
        d = np.abs(g - mean).sum(-1)
        tau = 3.0 * max(float(np.median(d[w > 0.5])) if (w > 0.5).any() else 0.0, 1e-3)
        k = 1.0 / (1.0 + (d / tau) ** 2)
    return k


def share_filled(circle: tuple[float, float, float], filled: np.ndarray) -> float:
    """The share of `circle`'s disc where the mates' background was filled in (a circle there
    is the fill's, not the press's); 1 for a circle off the frame."""
    own = _disc_box(*circle, filled.shape)
    if own is None:
        return 1.0
    box, disc = own
    return float(filled[box][disc].mean())
