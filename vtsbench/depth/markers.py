"""Marker gels: find the printed dots, and fill the gradient field over them.

Many GelSight-type gels carry a grid of small dark dots (markers) to track shear. They are not
surface shape: left in, the colour-to-gradient fit learns them as slopes, and the depth map and
the flat gel around a press carry their pattern. So:

1. `detect_markers(background, mm_per_px)` looks for a grid in the no-contact frame: dark blobs
   against the local median of the grey level (a window of about 2.5 mm, from the scale; a
   sixth of the shorter side without one), round and of one consistent size. It returns a
   `MarkerSpec` (the dots' diameter and the detection settings), or None when the gel shows no
   such dots. It is the one dot finder: circle detection takes the dots of the background and of
   the press (`marker_mask`) out of the colour change (`imprint.change_map`).
2. `marker_mask(images, spec, background_mask)` finds the dots in each frame (they move with
   the gel under a press) with the same test, keeps the blobs of the calibrated size, joins the
   dots of the background (the colour difference is disturbed there too) and grows the result
   by the dots' soft edge and the feature blur.
3. Calibration trains on the run time's colour difference (the dots divided back, step 4)
   and leaves out of the samples the dots' dark cores, where moved dots went and what is
   filled (`left_out_of_fit`): divided back, a dark core carries more noise than the gel
   between the dots. Their lighter parts and the ring they are grown by stay in.
4. At run time a dot is a multiplier on the light, in the frame as in the background: where
   it has not moved, `dot_correction` divides the colour difference by the dot's transmission
   per channel (`transmission`: the background over its harmonic fill across the dots), so
   the difference is the one the gel would show without it. A dot that moved under the press
   (a Lucas-Kanade step of the frame's transmission against the background's finds it
   shifted) is followed: Gauss-Newton on its transmission finds the shift, and over its old
   and new place the frame is divided by the shifted transmission and the background's
   dot-free level taken off (`DotCorrection`: gain and offset). Only what cannot be recovered
   so is masked: a dot's core darker than DOT_MIN_TRANSMISSION, and whole every dot that
   moved and cannot be followed (more than half a dot, or squeezed: its transmission is not
   the background's shifted) or shows up away from the background's. `fill_gradients` replaces the
   gradients over that mask by their harmonic fill from the pixels around it (Laplace's
   equation over the hole, a sparse solve), before the Poisson solve.

OpenCV does the image work (medianBlur, connectedComponentsWithStats, dilate); scipy.sparse
the fill.
"""

from __future__ import annotations

import hashlib
import math
import threading
from collections import OrderedDict
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

#: Side of the local-median window in mm (a few marker diameters; about one grid pitch).
WINDOW_MM = 2.5
#: A pixel is dark when its grey level is below (1 - CONTRAST) times the local median.
CONTRAST = 0.15
#: A grid: at least this many round blobs of one size in the background frame.
MIN_DOTS = 6
#: Blob area accepted around the median dot area (a dot is squeezed or stretched in a press).
AREA_RANGE = (0.35, 2.5)


@dataclass(frozen=True)
class MarkerSpec:
    """The marker dots of a gel, as found in its background frame."""

    diameter_px: float  # median dot diameter (equal-area) in the background
    window_px: int  # local-median window (odd)
    contrast: float = CONTRAST
    grow_px: int = 2  # mask growth beyond the thresholded dot (soft edge, feature blur)
    n_dots: int = 0  # dots found in the background
    dot_blur_px: float = 0.0  # the colour difference's blur on the dots (0: the plain blur)

    @property
    def area_px(self) -> float:
        return math.pi * self.diameter_px**2 / 4

    def to_dict(self) -> dict[str, Any]:
        return {"diameter_px": float(self.diameter_px), "window_px": int(self.window_px),
                "contrast": float(self.contrast), "grow_px": int(self.grow_px),
                "n_dots": int(self.n_dots), "dot_blur_px": float(self.dot_blur_px)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> MarkerSpec:
        # files written before the dots' own blur have none: their fit had none
        return cls(float(d["diameter_px"]), int(d["window_px"]), float(d["contrast"]),
                   int(d["grow_px"]), int(d.get("n_dots", 0)), float(d.get("dot_blur_px", 0.0)))


def window_px(mm_per_px: float | tuple[float, float] | None, shape: tuple[int, int]) -> int:
    """The local-median window (odd, 5 px up to half the shorter side) for a scale; without
    one, a sixth of the shorter side (wider than any dot of a grid of MIN_DOTS)."""
    k = min(shape) // 6 if mm_per_px is None else round(WINDOW_MM / _mm(mm_per_px))
    k = max(5, min(k, min(shape) // 2, 255))
    return k | 1


def _mm(mm_per_px: float | tuple[float, float]) -> float:
    return float(np.mean(mm_per_px)) if np.ndim(mm_per_px) else float(mm_per_px)


def _grey(image: np.ndarray) -> np.ndarray:
    import cv2

    img = np.ascontiguousarray(image)
    if img.dtype != np.uint8:
        img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    return cv2.cvtColor(img, cv2.COLOR_RGB2GRAY) if img.ndim == 3 else img


def _dark_blobs(image: np.ndarray, window: int, contrast: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """Labels (H, W) int32 of the dark blobs of one frame and their stats (n, 5) (cv2 layout:
    x, y, width, height, area; row 0 the background)."""
    import cv2

    grey = _grey(image)
    med = cv2.medianBlur(grey, window)
    dark = (grey.astype(np.float32) < med.astype(np.float32) * np.float32(1 - contrast))
    _, labels, stats, _ = cv2.connectedComponentsWithStats(dark.view(np.uint8), connectivity=8,
                                                           ltype=cv2.CV_32S)
    return labels, stats


def _round(stats: np.ndarray) -> np.ndarray:
    """Which blobs are round enough for a dot: bounding box near square and well filled."""
    w, h, area = stats[:, 2].astype(float), stats[:, 3].astype(float), stats[:, 4].astype(float)
    aspect = np.maximum(w, h) / np.maximum(np.minimum(w, h), 1)
    fill = area / np.maximum(w * h, 1)
    return (aspect <= 2.0) & (fill >= 0.45)


def detect_markers(background: np.ndarray, mm_per_px: float | tuple[float, float] | None,
                   contrast: float = CONTRAST, grow_px: int = 2) -> MarkerSpec | None:
    """The gel's marker dots as seen in its no-contact frame (H, W, 3), or None: at least
    MIN_DOTS round dark blobs of one size (within AREA_RANGE of their median), 2 px to 3 mm
    across (without a scale: to the local-median window, `window_px`). grow_px: how far the
    mask reaches beyond a thresholded dot (the feature blur's reach: 2 px for a 1 px blur)."""
    shape = background.shape[:2]
    win = window_px(mm_per_px, shape)
    _, stats = _dark_blobs(background, win, contrast)
    if stats.shape[0] <= 1:
        return None
    st = stats[1:]
    diam = np.sqrt(4 * st[:, 4] / math.pi)
    largest = win if mm_per_px is None else 3.0 / _mm(mm_per_px)
    ok = _round(st) & (diam >= 2.0) & (diam <= largest)
    if ok.sum() < MIN_DOTS:
        return None
    med = float(np.median(st[ok, 4]))
    same = ok & (st[:, 4] >= AREA_RANGE[0] * med) & (st[:, 4] <= AREA_RANGE[1] * med)
    if same.sum() < MIN_DOTS or same.sum() < 0.6 * ok.sum():
        return None
    d = float(np.sqrt(4 * med / math.pi))
    return MarkerSpec(diameter_px=d, window_px=win, contrast=contrast,
                      grow_px=int(grow_px), n_dots=int(same.sum()))


def _frame_mask(image: np.ndarray, spec: MarkerSpec) -> np.ndarray:
    """The dots of one frame: dark round blobs of the spec's size (not grown)."""
    labels, stats = _dark_blobs(image, spec.window_px, spec.contrast)
    area = stats[:, 4]
    h, w = labels.shape
    # a dot cut by the frame's edge is neither round nor whole: any part of one will do
    cut = (stats[:, 0] == 0) | (stats[:, 1] == 0) | (stats[:, 0] + stats[:, 2] == w) | \
        (stats[:, 1] + stats[:, 3] == h)
    keep = (_round(stats) & (area >= AREA_RANGE[0] * spec.area_px) | cut) & \
        (area <= AREA_RANGE[1] * spec.area_px)
    keep[0] = False
    return keep[labels]


def marker_mask(images: np.ndarray, spec: MarkerSpec,
                background: np.ndarray | None = None) -> np.ndarray:
    """(..., H, W) bool: the marker dots of each RGB frame (..., H, W, 3), joined with those of
    the background frame when given, grown by spec.grow_px."""
    import cv2

    arr = np.asarray(images)
    lead, (h, w) = arr.shape[:-3], arr.shape[-3:-1]
    frames = arr.reshape(-1, h, w, arr.shape[-1])
    base = None if background is None else _frame_mask(background, spec)
    g = spec.grow_px
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * g + 1, 2 * g + 1))
    out = np.empty((frames.shape[0], h, w), bool)
    for k, f in enumerate(frames):
        m = _frame_mask(f, spec)
        if base is not None:
            m |= base
        out[k] = cv2.dilate(m.view(np.uint8), kernel).view(bool)
    return out.reshape(*lead, h, w)


#: Below this transmission a dot's colour change is too faint to divide back (its noise and
#: quantisation would be amplified more than 1 / DOT_MIN_TRANSMISSION times): filled instead.
DOT_MIN_TRANSMISSION = 0.2


def transmission(background: np.ndarray, spec: MarkerSpec,
                 dots: np.ndarray | None = None) -> np.ndarray:
    """(H, W, 3) float32 share of the light each background pixel passes per channel: the
    background over its dot-free level (the harmonic fill of the background over its grown
    dots), clipped to (0, 1]; exactly 1 off the dots. dots: the background's grown dots
    (`marker_mask` of it alone), found when not given."""
    bg = np.asarray(background, np.float32)
    if dots is None:
        dots = marker_mask(background, spec)
    out = np.ones(bg.shape, np.float32)
    if dots.any():
        level = np.maximum(_harmonic(bg, dots), 1.0)
        out[dots] = np.clip(bg[dots] / level, 1e-3, 1.0)
    return out


def background_dots(background: np.ndarray, spec: MarkerSpec
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(transmission, grown dots) of the background: what every `dot_correction` of frames
    against it takes, found once."""
    dots = marker_mask(background, spec)
    return transmission(background, spec, dots), dots


#: A dot of the background has moved in a frame when the frame's own transmission there (the
#: frame over its harmonic fill across the dots) is the background's shifted by more than
#: MOVED_PX (one Lucas-Kanade step per dot), or departs from it by more than MOVED_SHARE of
#: the dot's darkness on average over the dot (a dot squeezed, lost or far away).
MOVED_PX, MOVED_SHARE = 0.5, 0.25
#: A moved dot is followed when its shifted transmission leaves at most this share of the
#: dot's darkness unexplained on average over the dot.
FOLLOW_SHARE = 0.25


#: On a marker gel the colour difference is blurred over the background's grown dots by
#: DOT_BLUR_MM (`MarkerSpec.dot_blur_px`; none where that is no wider than the calibration's
#: own blur) and by the calibration's blur elsewhere, blended across a soft edge of
#: DOT_BLUR_EDGE_PX: what a dot leaves once divided out (its noise lifted by 1 / transmission,
#: its edge, a JPEG's ringing of it) the mapping reads as slope. Simulated marker gels at
#: 0.05 mm/px, 16 presses held out in turn, against the same presses with ink-less dots: three
#: coloured lights 1.24 -> 1.17x landscape; at 0.06 mm/px, dots of 8 and 20 px through JPEG 70
#: -8 % error, losslessly -0.2 to -1.8 % (docs/depth.md, marker gels). A size in mm, not in
#: px: 3 px on Taxim's dots (0.1245 mm/px, contacts of 16 px) cost 3 % more error.
DOT_BLUR_MM = 0.15
DOT_BLUR_EDGE_PX = 1.0


def dot_blur_px(mm_per_px: float | tuple[float, float], blur_px: float) -> float:
    """The dots' blur (px) on a gel of this scale whose colour difference is blurred by blur_px
    elsewhere: DOT_BLUR_MM in pixels, or 0 (none of its own) where that is no wider."""
    px = round(DOT_BLUR_MM / _mm(mm_per_px), 3)
    return px if px > blur_px else 0.0


def dot_blur_weight(dots: np.ndarray) -> np.ndarray:
    """(H, W, 1) float32: the share of the dots' own blur at each pixel, 1 on the grown dots
    (H, W bool), falling to 0 across DOT_BLUR_EDGE_PX around them."""
    import cv2

    w = cv2.GaussianBlur(dots.astype(np.float32), (0, 0), DOT_BLUR_EDGE_PX,
                         borderType=cv2.BORDER_REFLECT_101)
    return np.clip(w, 0.0, 1.0, out=w)[..., None]


def blur_difference(frame: np.ndarray, blur_px: float, weight: np.ndarray | None = None,
                    wide_px: float = 0.0) -> np.ndarray:
    """One colour difference (H, W, 3) float32 blurred by blur_px (none at 0) and, on a marker
    gel, by wide_px where `weight` (`dot_blur_weight`) says: sharp + weight x (wide - sharp).
    The numpy run time and the build (`DepthMaker`) both blur through here."""
    import cv2

    sharp = frame if blur_px <= 0 else cv2.GaussianBlur(
        frame, (0, 0), blur_px, borderType=cv2.BORDER_REFLECT_101)
    if weight is None or wide_px <= 0:
        return sharp
    wide = cv2.GaussianBlur(frame, (0, 0), wide_px, borderType=cv2.BORDER_REFLECT_101)
    wide -= sharp
    wide *= weight
    wide += sharp
    return wide


@dataclass(frozen=True)
class DotCorrection:
    """How a marker gel's dots come out of the colour difference of frames (..., H, W, 3):
    (frame - background) * gain + offset is the difference the gel would show without them,
    and fill (..., H, W) marks the pixels where that cannot be done (to fill in the gradients).
    dots (H, W) are the background's grown dots the correction was made from (`marker_mask` of
    the background alone). offset is None where no dot was followed (then it is 0)."""

    gain: np.ndarray
    fill: np.ndarray
    dots: np.ndarray
    offset: np.ndarray | None = None
    wide_px: float = 0.0  # the difference's blur on the dots (MarkerSpec.dot_blur_px)

    @cached_property
    def blur_weight(self) -> np.ndarray | None:
        """Where the difference gets the dots' own blur (`dot_blur_weight` of `dots`), or None
        when they have none."""
        return dot_blur_weight(self.dots) if self.wide_px > 0 else None

    def apply(self, diff: np.ndarray) -> np.ndarray:
        """diff (frame - background, float32) corrected in place, and returned."""
        np.multiply(diff, self.gain, out=diff)
        if self.offset is not None:
            np.add(diff, self.offset, out=diff)
        return diff


def _follow(t_f: np.ndarray, t_bg: np.ndarray, region: np.ndarray, max_px: float
            ) -> tuple[float, float] | None:
    """The shift (dx, dy) px that carries a dot of the background transmission patch t_bg onto
    the frame's t_f (t_f(x) = t_bg(x - shift), least squares over `region`, Gauss-Newton from
    0), or None when it does not converge within max_px or leaves more than FOLLOW_SHARE of the
    dot's darkness unexplained (a dot squeezed or lost under the press)."""
    import cv2

    ph, pw = t_bg.shape
    yy, xx = np.mgrid[:ph, :pw].astype(np.float32)

    def shifted(u: np.ndarray) -> np.ndarray:
        return cv2.remap(t_bg, xx - np.float32(u[0]), yy - np.float32(u[1]), cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_REPLICATE)

    u = np.zeros(2)
    dark = float((1.0 - t_bg[region]).mean())
    for _ in range(8):
        t = shifted(u)
        gy, gx = (a[region] for a in np.gradient(t))
        r = t_f[region] - t[region]
        a = np.array([[gx @ gx, gx @ gy], [gx @ gy, gy @ gy]])
        if np.linalg.det(a) < 1e-9:
            return None
        du = -np.linalg.solve(a, np.array([gx @ r, gy @ r]))
        u += du
        if np.hypot(*u) > max_px:
            return None
        if np.hypot(*du) < 0.02:
            break
    t = shifted(u)
    if float(np.abs(t_f[region] - t[region]).mean()) > FOLLOW_SHARE * max(dark, 1e-6):
        return None
    return float(u[0]), float(u[1])


def dot_correction(images: np.ndarray, spec: MarkerSpec, background: np.ndarray,
                   trans: np.ndarray, dots: np.ndarray | None = None) -> DotCorrection:
    """The correction (`DotCorrection`) of RGB frames (..., H, W, 3) on a marker gel.

    A dot multiplies the light of the frame and of the background alike, so where it has not
    moved the difference is divided by its transmission `trans` (`transmission`). A dot that
    moved under the press (MOVED_PX, MOVED_SHARE) is followed: its shift is found by
    Gauss-Newton on its transmission (`_follow`), and over the dot's old and new place the
    frame is divided by the shifted transmission and the background's dot-free level taken
    off (gain and offset). Filled: a dot's core darker than DOT_MIN_TRANSMISSION (where it
    lies in the frame); whole, every moved dot that cannot be followed and every dot of the
    frame away from the background's; all grown by spec.grow_px (the feature blur's reach).
    dots, the background's grown dots (`marker_mask` of it alone), are found when not given."""
    import cv2

    arr = np.asarray(images)
    lead, (h, w) = arr.shape[:-3], arr.shape[-3:-1]
    frames = arr.reshape(-1, h, w, arr.shape[-1])
    if dots is None:
        dots = marker_mask(background, spec)  # the grown dots: their rim is dot-free gel
    n, labels, stats, _ = cv2.connectedComponentsWithStats(dots.view(np.uint8), connectivity=8,
                                                           ltype=cv2.CV_32S)
    t_bg = trans.mean(axis=-1)
    dark = t_bg < DOT_MIN_TRANSMISSION
    lab = labels[dots]
    depth = np.bincount(lab, 1.0 - t_bg[dots], n)
    ty, tx = (a[dots] for a in np.gradient(t_bg))
    sxx, sxy, syy = (np.bincount(lab, a * b, n) for a, b in ((tx, tx), (tx, ty), (ty, ty)))
    det = np.maximum(sxx * syy - sxy * sxy, 1e-12)
    g = spec.grow_px
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * g + 1, 2 * g + 1))
    base_gain = 1.0 / np.maximum(trans, DOT_MIN_TRANSMISSION)
    level = background.astype(np.float32) / np.maximum(trans, 1e-3)  # the dot-free background
    fill = np.empty((frames.shape[0], h, w), bool)
    gain = offset = None  # per frame, made at the first dot followed
    pad = g + math.ceil(spec.diameter_px / 2)
    for k, f in enumerate(frames):
        grey = f.astype(np.float32).mean(axis=-1)
        t_f = np.ones((h, w), np.float32)
        if dots.any():
            lev = np.maximum(_harmonic(grey[..., None], dots)[:, 0], 1.0)
            t_f[dots] = grey[dots] / lev
        dt = (t_f - t_bg)[dots]
        bx, by = np.bincount(lab, dt * tx, n), np.bincount(lab, dt * ty, n)
        shift = np.hypot(syy * bx - sxy * by, sxx * by - sxy * bx) / det
        moved = (shift > MOVED_PX) | \
            (np.bincount(lab, np.abs(dt), n) > MOVED_SHARE * np.maximum(depth, 1e-6))
        moved[0] = False
        hole_dark = dark.copy()
        for c in np.flatnonzero(moved):
            x0, y0, bw, bh = (int(v) for v in stats[c, :4])
            ys = slice(max(0, y0 - pad), min(h, y0 + bh + pad))
            xs = slice(max(0, x0 - pad), min(w, x0 + bw + pad))
            own = labels[ys, xs]
            u = _follow(t_f[ys, xs], t_bg[ys, xs].astype(np.float32), own == c,
                        spec.diameter_px / 2)
            if u is None:
                continue
            pw_, ph_ = xs.stop - xs.start, ys.stop - ys.start
            yy, xx = np.mgrid[:ph_, :pw_].astype(np.float32)
            mx, my = xx - np.float32(u[0]), yy - np.float32(u[1])
            ts = cv2.remap(np.ascontiguousarray(trans[ys, xs]), mx, my, cv2.INTER_LINEAR,
                           borderMode=cv2.BORDER_REPLICATE)
            # the dot's old and new place, not a neighbour's
            here = ((own == c) | ((own == 0) & (ts.mean(axis=-1) < 1.0)))
            if gain is None:
                gain = np.repeat(base_gain[None], frames.shape[0], axis=0)
                offset = np.zeros_like(gain)
            gk = 1.0 / np.maximum(ts, DOT_MIN_TRANSMISSION)
            gain[k, ys, xs][here] = gk[here]
            offset[k, ys, xs][here] = (background[ys, xs].astype(np.float32) * gk
                                       - level[ys, xs])[here]
            core = hole_dark[ys, xs]
            core[here] = ts.mean(axis=-1)[here] < DOT_MIN_TRANSMISSION
            moved[c] = False
        # the frame's dots that touch none of the background's
        fl, fst = cv2.connectedComponentsWithStats(_frame_mask(f, spec).view(np.uint8),
                                                   connectivity=8, ltype=cv2.CV_32S)[1:3]
        touch = np.zeros(fst.shape[0], bool)
        touch[fl[dots]] = True
        touch[0] = True
        hole = moved[labels] | ~touch[fl] | hole_dark
        fill[k] = cv2.dilate(hole.view(np.uint8), kernel).view(bool)
    if gain is None:
        return DotCorrection(np.broadcast_to(base_gain, arr.shape), fill.reshape(*lead, h, w),
                             dots, wide_px=spec.dot_blur_px)
    return DotCorrection(gain.reshape(arr.shape), fill.reshape(*lead, h, w), dots,
                         offset.reshape(arr.shape), spec.dot_blur_px)


def corrected(corr: DotCorrection) -> np.ndarray:
    """(..., H, W) bool: what a fit should not learn from, the pixels a correction touches:
    the background's grown dots (`DotCorrection.dots`), where a moved dot
    went (its gain is not 1) and what is filled. Unlike `marker_mask` of a press it takes no
    dark blob of the press for a dot where no dot of the background lies or moved: such a blob
    can be a dot merged with a dark lobe of the imprint, which the run time leaves as it is."""
    return corr.dots | (np.asarray(corr.gain) != 1.0).any(axis=-1) | corr.fill


#: A fit learns from a still dot's pixels divided back where the dot passes at least this share
#: of the light (their noise at most doubled), and from the dot-free ring the dots are grown by.
#: Left out: the darker cores, where the division's noise would bias the fit towards flat.
#: Simulated marker gels at JPEG 60-90, 4:2:0 (4 folds, exact circles), all left out against
#: this: 1.27 / 1.23 / 1.23 / 1.25x the same presses without markers against 1.24 / 1.18 /
#: 1.18 / 1.18x (`zones3`, `sides4`, landscape and portrait); 0.2 (every divided pixel): 1.31x.
FIT_MIN_TRANSMISSION = 0.5


def left_out_of_fit(corr: DotCorrection, trans: np.ndarray) -> np.ndarray:
    """(..., H, W) bool: what a fit should not learn from, of the pixels a correction touches
    (`corrected`): a still dot's core darker than FIT_MIN_TRANSMISSION, where a moved dot went
    and what is filled. trans: the background's transmission the correction was made with."""
    out = corrected(corr)
    base_gain = 1.0 / np.maximum(trans, DOT_MIN_TRANSMISSION)
    still = np.all(np.asarray(corr.gain) == base_gain, axis=-1)
    if corr.offset is not None:
        still &= ~np.asarray(corr.offset).any(axis=-1)
    learnt = still & (trans.mean(axis=-1) >= FIT_MIN_TRANSMISSION) & ~corr.fill
    return out & ~learnt


def fill_gradients(g: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(..., H, W, 2) gradients with the masked pixels replaced by the harmonic fill of the
    unmasked ones around them: Laplace's equation (5-point) over each hole, the hole's rim as
    its boundary, so a linear field is filled exactly. A hole with no unmasked neighbour gets 0.
    """
    g = np.array(g, np.float32, copy=True)
    h, w = g.shape[-3:-1]
    gf = g.reshape(-1, h, w, 2)
    mf = np.broadcast_to(mask, g.shape[:-1]).reshape(-1, h, w)
    for k in range(gf.shape[0]):
        if mf[k].any():
            gf[k][mf[k]] = _harmonic(gf[k], mf[k])
    return g


def _harmonic(g: np.ndarray, m: np.ndarray) -> np.ndarray:
    """(n, C) harmonic values at the n masked pixels of one frame (H, W, C) (float32)."""
    return _laplace(m).solve(g)


class _Laplace:
    """Laplace's equation (5-point) over the masked pixels of one (H, W) mask, the unmasked
    neighbours as the boundary: the sparse matrix factorised once (SuperLU), solved for any
    frame's boundary values."""

    def __init__(self, m: np.ndarray) -> None:
        import scipy.sparse
        import scipy.sparse.linalg

        h, w = m.shape
        ys, xs = np.nonzero(m)
        n = self.n = ys.size
        index = np.full((h, w), -1, np.int64)
        index[ys, xs] = np.arange(n)
        diag = np.full(n, 1e-9)  # a hole without unmasked neighbours is held at 0
        rows, cols, b_i, b_y, b_x = [], [], [], [], []
        ids = np.arange(n)
        for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
            ny, nx = ys + dy, xs + dx
            inside = (ny >= 0) & (ny < h) & (nx >= 0) & (nx < w)
            i, ny, nx = ids[inside], ny[inside], nx[inside]
            diag[i] += 1.0
            nb = index[ny, nx]
            hole = nb >= 0
            rows.append(i[hole])
            cols.append(nb[hole])
            b_i.append(i[~hole])
            b_y.append(ny[~hole])
            b_x.append(nx[~hole])
        r, c = np.concatenate(rows), np.concatenate(cols)
        a = scipy.sparse.csc_matrix((np.concatenate([diag, -np.ones(r.size)]),
                                     (np.concatenate([ids, r]), np.concatenate([ids, c]))),
                                    shape=(n, n))
        self.lu = scipy.sparse.linalg.splu(a)
        self.b_i, self.b_y, self.b_x = (np.concatenate(v) for v in (b_i, b_y, b_x))

    def solve(self, g: np.ndarray) -> np.ndarray:
        """(n, C) float32: the harmonic values for a frame (H, W, C)."""
        vals = g[self.b_y, self.b_x].astype(np.float64)
        rhs = np.stack([np.bincount(self.b_i, vals[:, k], self.n)
                        for k in range(vals.shape[1])], axis=1)
        return self.lu.solve(rhs).astype(np.float32)


#: Factorised systems kept, most recently used last: a marker gel's background dots (the same in
#: every frame) and its fill masks (the same in frames whose dots did not move). Refactorising
#: per frame was 300 of the 470 ms of `dot_correction` on a 480x640 frame with 19 % dots.
_SYSTEMS: OrderedDict[tuple[tuple[int, ...], bytes], _Laplace] = OrderedDict()
_SYSTEMS_MAX = 4
_SYSTEMS_LOCK = threading.Lock()


def _laplace(m: np.ndarray) -> _Laplace:
    """The factorised system of mask m, from _SYSTEMS when the same mask was seen lately."""
    key = (m.shape, hashlib.blake2b(np.packbits(m).tobytes(), digest_size=16).digest())
    with _SYSTEMS_LOCK:
        hit = _SYSTEMS.get(key)
        if hit is not None:
            _SYSTEMS.move_to_end(key)
            return hit
    system = _Laplace(np.ascontiguousarray(m, bool))
    with _SYSTEMS_LOCK:
        _SYSTEMS[key] = system
        while len(_SYSTEMS) > _SYSTEMS_MAX:
            _SYSTEMS.popitem(last=False)
    return system
