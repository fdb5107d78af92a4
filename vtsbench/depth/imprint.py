"""Where a ball press changed the gel's colour, before any edge is looked at: a change map that
ignores a marker grid, and the disc that best explains the whole change.

A marker gel carries small dark dots on a regular grid. Their darkness scales every colour
change that falls on them, so the change map shows holes where a dot lies; and the gel flows
under a press, so the dots in and around a contact move, each leaving a crescent of change
where it was and where it went. The calibration's dot finder (`markers.detect_markers`: round
dark blobs well below their surroundings, many of one size) finds the dots of the background
and of the press; `change_map` divides the change on a background dot by the dot's
transmission, holds the change on every dot of either frame to at most what the gel around it
shows (`DOT_CLIP`: a moved dot's crescent stands far above it, a still dot's change does not)
and fills the darkest pixels from around them (normalised convolution), so the map describes
the imprint, not the grid. A channel the press drives to the top of the frame's range, where
the background is below it, is restored from the other two (`restore_clipped`), so that a
clipped lobe's change ends at the rim, not where the clipping does.

`disc_search` scores discs over the plausible radius range by how well the disc covers the
changed pixels: +1 for a changed pixel inside it, -1 for an unchanged one. The best disc is the
one the whole change supports, so a small strong feature (a dot of dirt, a saturated glint)
cannot win over a contact many times its size, and a radius range taken from the ball and the
scale keeps it from doing so even where the feature is stronger than the whole contact.
"""

from __future__ import annotations

import math

import numpy as np


def _grey_and_level(background: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The background's grey level and its median over a window wider than any marker dot."""
    import cv2

    from .markers import window_px

    grey = background.astype(np.float32).mean(axis=-1) if background.ndim == 3 else \
        background.astype(np.float32)
    k = window_px(None, grey.shape)
    local = cv2.medianBlur(np.clip(grey, 0, 255).astype(np.uint8), k)
    return grey, np.maximum(local.astype(np.float32), 1.0)


#: On a dot, the change is divided by the dot's darkness (the dot scales the light that reaches
#: the camera, in the press as in the background) down to this transmission; darker pixels
#: are filled from around them.
DOT_MIN_GAIN = 0.4

#: On any dot of either frame the change is held to at most DOT_CLIP times the change filled
#: in from the gel around the dots, plus twice that fill's median (the noise). A dot that moved
#: under the press leaves a crescent divided up to 2.5 times that stands far above what is
#: around it; a still dot's divided change does not. Measured on the real sets with a real
#: marker grid, moved outward by a tenth of the contact radius at the rim or not, and on the
#: simulator's marker gels (`benchmarks/circles_variants.py`, `circles_sim_variants.py`, in
#: docs/depth.md): without the hold (division alone) DIGIT moved kept 14 % of centres within
#: 3 px of the labels and dropped one press (6 rotated with JPEG); at 1.0, 57 % and none (the
#: two presses under another light rotated with JPEG); at 1.25, 64 % and none (43 % rotated
#: with JPEG); at 1.5, 50 % and none (4 rotated); at 2, 43 % and 2 (4). Filling every dot
#: instead of dividing (the limit of a hold at 0) cost the simulated marker gels the rim under
#: dots as wide as a contact (detected circles 1.32x the depth error without markers where 1.0
#: gives 1.24x, 1.25 gives 1.18x and division alone 1.18x).
DOT_CLIP = 1.0


def _fill(d: np.ndarray, mask: np.ndarray, sigma: float) -> np.ndarray:
    """d with the masked pixels replaced by the Gaussian-weighted mean of the unmasked ones."""
    import cv2

    keep = (~mask).astype(np.float32)
    num = cv2.GaussianBlur(d * keep, (0, 0), sigma)
    den = cv2.GaussianBlur(keep, (0, 0), sigma)
    filled = num / np.maximum(den, 1e-12)
    return np.where(mask & (den > 1e-12), filled, d).astype(np.float32)


#: The smooth drift between a press and its background (light that changed, a background frame
#: taken at another time, auto exposure) is a quadratic per channel fitted over a grid of about
#: DRIFT_GRID cells a side, iterated DRIFT_ROUNDS times without the pixels that stand out of it.
DRIFT_GRID, DRIFT_ROUNDS = 60, 4


def drift(d: np.ndarray) -> np.ndarray:
    """The smooth part (float32 H x W x C) of a signed colour difference `d` (H x W x C): a
    quadratic in x and y per channel, robustly fitted (a press's imprint is left out as what
    stands out of the fit), so that only a local change remains once it is taken off."""
    h, w = d.shape[:2]
    step = max(1, min(h, w) // DRIFT_GRID)
    ys, xs = np.mgrid[step // 2:h:step, step // 2:w:step]
    u, v = (xs.ravel() / w - 0.5) * 2, (ys.ravel() / h - 0.5) * 2
    basis = np.column_stack([np.ones_like(u), u, v, u * u, u * v, v * v])
    out = np.empty(d.shape, np.float32)
    yy, xx = np.mgrid[:h, :w]
    uu, vv = (xx.ravel() / w - 0.5) * 2, (yy.ravel() / h - 0.5) * 2
    full = np.column_stack([np.ones_like(uu), uu, vv, uu * uu, uu * vv, vv * vv])
    for c in range(d.shape[2]):
        val = d[ys, xs, c].ravel().astype(np.float64)
        keep = np.ones(val.size, bool)
        coef = np.zeros(6)
        for _ in range(DRIFT_ROUNDS):
            if keep.sum() < 12:
                break
            coef, *_ = np.linalg.lstsq(basis[keep], val[keep], rcond=None)
            res = val - basis @ coef
            mad = float(np.median(np.abs(res[keep]))) * 1.4826
            keep = np.abs(res) <= max(3 * mad, 2.0)
        out[..., c] = (full @ coef).reshape(h, w)
    return out


#: A pixel of a channel is clipped when the press reaches the top of the frame's range less
#: CLIP_MARGIN there and the background does not; a channel is restored when at least
#: CLIP_MIN_PIXELS are, from a fit over at least FIT_MIN_PIXELS changed pixels none of whose
#: channels comes within CLIP_NEAR of the top; changed: FIT_LEVEL robust deviations above the
#: median change.
CLIP_MARGIN, CLIP_NEAR, CLIP_MIN_PIXELS, FIT_MIN_PIXELS, FIT_LEVEL = 1, 5, 10, 30, 6.0
#: The fit takes an even sample of at most this many changed pixels.
FIT_MAX_PIXELS = 4000


def restore_clipped(res: np.ndarray, image: np.ndarray, background: np.ndarray) -> np.ndarray:
    """The press's colour change `res` (float32 H x W x 3, drift taken off) with each channel's
    clipped pixels raised to what the other two channels' change predicts there.

    A bright lobe that clips hides how far the press raised that channel: its change is a
    plateau that ends where the clipping does, and the rim on that side is read there (DIGIT
    presses under coloured light ramps: circles 10-29 px off). Under side lights each
    channel's change is close to a linear function of the surface slope, so one channel is
    close to a linear combination of the other two: the combination is fitted by least
    squares (two rounds without the pixels beyond 3 robust deviations) over the changed
    pixels that clip in no channel, and a clipped pixel takes the larger of its prediction
    and what was recorded (the recorded change is a lower bound, never lowered). R^2 of the
    fit: 0.71-0.93 on Taxim's presses, 0.5-0.88 on DIGIT's but 0012 at the frame's edge
    (0.03-0.32, its circle left where it was). Frames without clipping, or not of unsigned
    integers, come back as they are."""
    if res.shape[-1] != 3 or image.shape != background.shape or image.size == 0 or \
            image.dtype.kind not in "u" or image.dtype != background.dtype:
        return res
    top = np.iinfo(image.dtype).max
    if image.max() < top - CLIP_MARGIN:  # most frames: 0.01 ms, where the masks take 1-4.5
        return res
    # per channel: numpy's reductions over a last axis of 3 took 6 of 7 ms at 320x240
    chans = range(3)
    clipped = [(image[..., c] >= top - CLIP_MARGIN) & (background[..., c] < top - CLIP_MARGIN)
               for c in chans]
    todo = [c for c in chans if np.count_nonzero(clipped[c]) >= CLIP_MIN_PIXELS]
    if not todo:
        return res
    near = np.zeros(image.shape[:2], bool)
    for c in chans:
        near |= (image[..., c] >= top - CLIP_NEAR) | (background[..., c] >= top - CLIP_NEAR)
    mag = np.abs(res[..., 0]) + np.abs(res[..., 1]) + np.abs(res[..., 2])
    med, mad = noise_levels(mag)
    fit = ~near & (mag > max(med + FIT_LEVEL * mad, med + 4.0))
    n_fit = int(fit.sum())
    if n_fit < FIT_MIN_PIXELS:
        return res
    if n_fit > FIT_MAX_PIXELS:  # an even sample of them: three parameters need no more
        fit &= (np.cumsum(fit.ravel()).reshape(fit.shape) % -(-n_fit // FIT_MAX_PIXELS)) == 0
    out = res.copy()
    for c in todo:
        where = clipped[c]
        o1, o2 = (k for k in chans if k != c)
        a = np.column_stack([res[..., o1][fit], res[..., o2][fit],
                             np.ones(int(fit.sum()), np.float32)]).astype(np.float64)
        y = res[..., c][fit]
        keep = np.ones(y.size, bool)
        for _ in range(3):
            coef, *_ = np.linalg.lstsq(a[keep], y[keep], rcond=None)
            err = np.abs(y - a @ coef)
            keep = err <= 3 * 1.4826 * float(np.median(err[keep])) + 1.0
            if keep.sum() < FIT_MIN_PIXELS:
                break
        pred = coef[0] * res[..., o1][where] + coef[1] * res[..., o2][where] + coef[2]
        out[..., c][where] = np.maximum(res[..., c][where], pred)
    return out


def change_map(image: np.ndarray, background: np.ndarray, sigma: float,
               dots: tuple[np.ndarray, np.ndarray, float] | None = None) -> np.ndarray:
    """Blurred sum over channels of |image - background - drift| (float32, H x W; `drift`: the
    smooth light change between the two taken off). With `dots` (the background's dots, the
    dots of either frame, both H x W bool grown as `markers.marker_mask` grows them, and their
    diameter in px) the change on a background dot is divided by the dot's transmission (its
    grey level over the level around it), held on any dot to DOT_CLIP times the change filled
    in from around the dots, and filled from around where the dot is darker than DOT_MIN_GAIN."""
    import cv2

    sd = image.astype(np.float32) - background.astype(np.float32)
    if sd.ndim == 2:
        sd = sd[..., None]
    d = np.abs(restore_clipped(sd - drift(sd), image, background)).sum(axis=-1)
    if dots is not None:
        still, either, diameter = dots
        sigma_fill = max(1.0, diameter / 4)
        grey, local = _grey_and_level(background)
        gain = np.clip(grey / local, 0.0, 1.0)
        d = np.where(still & (gain >= DOT_MIN_GAIN), d / np.maximum(gain, DOT_MIN_GAIN), d)
        around = _fill(d, either, sigma_fill)
        hold = DOT_CLIP * around + 2 * float(np.median(around))
        d = np.where(either, np.minimum(d, hold), d)
        d = _fill(d, still & (gain < DOT_MIN_GAIN), sigma_fill)
    return cv2.GaussianBlur(d, (0, 0), sigma) if sigma > 0 else d


def noise_levels(m: np.ndarray) -> tuple[float, float]:
    """(median, robust standard deviation) of a change map."""
    med = float(np.median(m))
    return med, float(np.median(np.abs(m - med))) * 1.4826 + 1e-3


def changed(m: np.ndarray, level: float = 5.0) -> np.ndarray:
    """The pixels whose change stands above the noise and the sensor's small drifts (bool):
    `level` robust deviations above the median change."""
    med, mad = noise_levels(m)
    return m > max(med + level * mad, med + 4.0)


#: The levels (robust deviations) at which `disc_search` counts a pixel as changed on a press
#: whose background differs by more than noise (another light: a texture of 11-17 DN robust
#: deviation where the press's own background gives 2-3.5 DN), where at 5 deviations only the
#: imprint's brightest lobe stands out. How far the texture reaches is not known beforehand,
#: so each is tried and the circle whose rim stands out most is kept (`sphere.detect_circle`).
#: DIGIT 0016 with a real marker grid: rim contrast 3.9 at 2.5 (its imprint), 3.4 at 3-3.5 (a
#: circle 5 px off); rotated, the grid moved and JPEG: 3.6 at 2.5, nothing at 3-4; 0017 with
#: the grid filled instead of divided: 1.1 at 2.5-3 (a texture patch), 4.0 at 3.5-4.
TEXTURE_LEVELS = (2.5, 3.0, 3.5, 4.0)


def disc_search(m: np.ndarray, r_range: tuple[float, float], n_radii: int = 14,
                level: float = 5.0) -> tuple[float, float, float, float] | None:
    """(x, y, r, changed pixels in it) of the disc, radius within r_range, that best covers the
    changed pixels of the change map `m` (`changed` at `level`; +1 each changed pixel inside,
    -1 each unchanged one), or None when no disc holds more changed pixels than unchanged ones.
    Searched on a grid coarsened so the smallest radius spans about 5 cells."""
    import cv2

    b = changed(m, level)
    if not b.any():
        return None
    r_lo, r_hi = float(r_range[0]), float(r_range[1])
    f = max(1, int(r_lo // 5))
    h, w = m.shape
    a = b.astype(np.float32) * 2 - 1
    if f > 1:
        a = cv2.resize(a, (max(1, w // f), max(1, h // f)), interpolation=cv2.INTER_AREA)
    best: tuple[float, float, float, float] | None = None
    top = -math.inf
    for r in np.geomspace(r_lo, max(r_hi, r_lo * 1.01), n_radii):
        rc = r / f
        k = math.ceil(rc)
        yy, xx = np.mgrid[-k:k + 1, -k:k + 1]
        disc = (np.hypot(xx, yy) <= rc).astype(np.float32)
        s = cv2.filter2D(a, -1, disc, borderType=cv2.BORDER_CONSTANT)
        i = int(np.argmax(s))
        if float(s.flat[i]) > top:
            top = float(s.flat[i])
            yi, xi = divmod(i, s.shape[1])
            best = ((xi + 0.5) * f - 0.5, (yi + 0.5) * f - 0.5, float(r), top * f * f)
    if best is None or top <= 0:
        return None
    return best


def ring_contrast(m: np.ndarray, circle: tuple[float, float, float]) -> float:
    """How far the change just inside a circle (0.7-1 r) stands above the change just outside
    it (1.3-1.8 r), in robust deviations of the change beyond 2 r (the texture away from the
    imprint; the whole map when little lies there): a robust z-score of the rim's step, which a
    circle fitted to texture or noise does not reach (measured: 3.0 at most on DIGIT 0016's
    texture and 2.2 on rendered frames without contact, 4.2-4.5 on the two DIGIT presses under
    another light, 9.5-38 on the others)."""
    x, y, r = circle
    h, w = m.shape
    yy, xx = np.ogrid[:h, :w]
    rho = np.hypot(xx - x, yy - y)
    inner, outer = m[(rho >= 0.7 * r) & (rho <= r)], m[(rho >= 1.3 * r) & (rho <= 1.8 * r)]
    if inner.size == 0 or outer.size == 0:
        return 0.0
    far = m[rho > 2 * r]
    _, mad = noise_levels(far if far.size >= 100 else m)
    return float((np.median(inner) - np.median(outer)) / mad)
