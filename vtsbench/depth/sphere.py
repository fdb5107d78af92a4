"""The calibration ball: its gradients and depth inside the contact circle, and finding the circle.

A ball of radius R pressed into the gel leaves a spherical cap inside the contact circle (centre
xc, yc; radius r). With rho the distance to the centre (all in mm, y down the rows):

    p = dD/dx = -(x - xc) / sqrt(R^2 - rho^2)
    q = dD/dy = -(y - yc) / sqrt(R^2 - rho^2)
    D = sqrt(R^2 - rho^2) - sqrt(R^2 - r^2)        (0 at the rim, positive into the gel)

Rim handling (`Rim`): the slope grows without bound towards the ball's equator and jumps at the
contact edge, where the gel leaves the ball and a labelled or detected circle is least sure, so
only pixels well inside the circle are trusted as training labels:

    trusted = rho <= r - max(shrink_px, shrink_frac * r)   and   slope <= max_slope
    flat    = rho >= r + max(r, flat_margin_mm)            (zero gradient: the gel is flat there)

The ring between the two is left out of training altogether: the gel around a contact is dragged
down into a skirt whose shape the sphere does not describe. A circle radius of at least
`max_radius_frac` of the ball radius (hand-marked circles are often a little too large) is
clamped to it before taking sqrt(R^2 - r^2), so every value is finite.

`detect_circle` finds an unlabelled contact from the difference to the no-contact background (the
smooth light drift taken off, marker dots taken out: `imprint.change_map`): two first centres,
the largest strong-change component with the lobes beside it and the disc that best covers the
whole change over the radii the ball can press (`radius_range`, `imprint.disc_search`), then
sub-pixel edge points along rays from each (the steepest fall of the change past its peak: the
colour changes most where the cap is steepest, at its rim), a RANSAC circle within that radius
range, and a weighted geometric least-squares fit to its inliers.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from .imprint import TEXTURE_LEVELS, ring_contrast


@dataclass(frozen=True)
class Rim:
    """How the rim of the contact and the gel around it are treated (see the module doc)."""

    shrink_px: float = 2.0
    shrink_frac: float = 0.06
    max_slope: float = 2.5
    flat_margin_mm: float = 1.5
    max_radius_frac: float = 0.97

    def to_dict(self) -> dict[str, float]:
        return {k: float(v) for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, d: dict) -> Rim:
        names = {f.name for f in fields(cls)}
        return cls(**{k: float(v) for k, v in d.items() if k in names})

    def shrink(self, r_px: float) -> float:
        """Pixels taken off the contact radius before labels are trusted."""
        return max(self.shrink_px, self.shrink_frac * r_px)

    def flat_radius(self, r_px: float, mm_per_px: float) -> float:
        """Distance from the centre (px) beyond which the gel counts as flat."""
        return r_px + max(r_px, self.flat_margin_mm / mm_per_px)


@dataclass
class SphereFields:
    """The sphere model of one press over the frame (float32 maps, bool masks)."""

    p: np.ndarray  # dD/dx, mm/mm; 0 outside the contact
    q: np.ndarray  # dD/dy, mm/mm (y down the rows)
    depth_mm: np.ndarray  # cap depth, 0 at the rim and outside
    contact: np.ndarray  # rho < r
    trusted: np.ndarray  # training labels of the cap (rim handling applied)
    flat: np.ndarray  # far from the contact: zero-gradient samples
    r_px: float  # contact radius used (after clamping)


def _scale(mm_per_px: float | tuple[float, float]) -> tuple[float, float]:
    if isinstance(mm_per_px, (int, float)):
        return float(mm_per_px), float(mm_per_px)
    return float(mm_per_px[0]), float(mm_per_px[1])


def ball_radius_px(ball_radius_mm: float, mm_per_px: float | tuple[float, float]) -> float:
    """The ball radius in pixels (geometric mean of the two scales when anisotropic)."""
    mx, my = _scale(mm_per_px)
    return ball_radius_mm / math.sqrt(mx * my)


def clamp_radius(r_px: float, ball_radius_mm: float, mm_per_px: float | tuple[float, float],
                 rim: Rim = Rim()) -> float:
    """The contact radius (px) clamped below the ball radius by `rim.max_radius_frac`."""
    return min(float(r_px), rim.max_radius_frac * ball_radius_px(ball_radius_mm, mm_per_px))


def cap_depth_mm(r_px: float, ball_radius_mm: float,
                 mm_per_px: float | tuple[float, float]) -> float:
    """Depth (mm) of a cap whose contact radius is r_px: R - sqrt(R^2 - r^2)."""
    mx, my = _scale(mm_per_px)
    r_mm = r_px * math.sqrt(mx * my)
    return ball_radius_mm - math.sqrt(max(ball_radius_mm**2 - r_mm**2, 0.0))


def sphere_fields(shape: tuple[int, int], x: float, y: float, r_px: float,
                  ball_radius_mm: float, mm_per_px: float | tuple[float, float],
                  rim: Rim = Rim()) -> SphereFields:
    """Gradients, depth and masks of a ball press centred at (x, y) px with contact radius r_px.

    The radius is clamped (see `clamp_radius`); the square root is floored at its value on the
    clamped rim, so every output is finite even for a circle as large as the ball.
    """
    h, w = shape
    mx, my = _scale(mm_per_px)
    s = math.sqrt(mx * my)
    r_px = clamp_radius(r_px, ball_radius_mm, (mx, my), rim)
    big_r = float(ball_radius_mm)
    r_mm = r_px * s
    dx = ((np.arange(w, dtype=np.float64) - x) * mx)[None, :]
    dy = ((np.arange(h, dtype=np.float64) - y) * my)[:, None]
    rho2 = dx**2 + dy**2
    rho_px = np.sqrt(rho2) / s
    contact = rho_px < r_px
    root = np.sqrt(np.maximum(big_r**2 - rho2, big_r**2 - r_mm**2))
    rim_root = math.sqrt(big_r**2 - r_mm**2)
    p = np.where(contact, -dx / root, 0.0)
    q = np.where(contact, -dy / root, 0.0)
    depth = np.where(contact, root - rim_root, 0.0)
    slope = np.sqrt(rho2) / root
    trusted = (rho_px <= r_px - rim.shrink(r_px)) & (slope <= rim.max_slope)
    flat = rho_px >= rim.flat_radius(r_px, s)
    return SphereFields(p.astype(np.float32), q.astype(np.float32), depth.astype(np.float32),
                        contact, trusted, flat, r_px)


# -- contact detection -----------------------------------------------------------------------


#: The last background's marker grid and grown dot mask (read-only), by a digest of its pixels:
#: every press of a set is compared with the same background, up to three times a press. A
#: marker press's change map at 480x640 took 65-74 ms finding them each time, 51-60 ms found
#: once (medians of 7, two runs; 2 cores, AMD EPYC).
_BACKGROUND_DOTS: dict[bytes, tuple[Any, np.ndarray | None]] = {}


def _background_dots(background: np.ndarray) -> tuple[Any, np.ndarray | None]:
    """The background's marker grid (None without one) and its grown dots, found once."""
    import hashlib

    from .markers import detect_markers, marker_mask

    bg = np.ascontiguousarray(background)
    key = f"{bg.shape}{bg.dtype}".encode() + hashlib.blake2b(bg.data, digest_size=16).digest()
    hit = _BACKGROUND_DOTS.get(key)
    if hit is None:
        spec = detect_markers(bg, None)
        still = None if spec is None else marker_mask(bg, spec)
        if still is not None:
            still.flags.writeable = False
        hit = (spec, still)
        _BACKGROUND_DOTS.clear()
        _BACKGROUND_DOTS[key] = hit
    return hit


def change_map(image: np.ndarray, background: np.ndarray, sigma: float,
               markers: bool = False) -> np.ndarray:
    """Blurred sum over channels of |image - background| (float32, H x W); markers: when the
    background shows a marker grid, its dots and the image's are taken out first
    (`imprint.change_map`)."""
    from .imprint import change_map as imprint_change
    from .markers import marker_mask

    spec, still = _background_dots(background) if markers else (None, None)
    if spec is None or still is None:
        return imprint_change(image, background, sigma, None)
    # grown dots: the union's growth is the grown union
    return imprint_change(image, background, sigma,
                          (still, still | marker_mask(image, spec), spec.diameter_px))


def fit_circle(xs: np.ndarray, ys: np.ndarray, weights: np.ndarray | None = None
               ) -> tuple[float, float, float]:
    """Least-squares (algebraic, Kasa) circle through points, optionally weighted: (x, y, r)."""
    xs, ys = np.asarray(xs, np.float64), np.asarray(ys, np.float64)
    w = np.ones_like(xs) if weights is None else np.sqrt(np.asarray(weights, np.float64))
    xm, ym = xs.mean(), ys.mean()
    u, v = xs - xm, ys - ym
    a = np.column_stack([u, v, np.ones_like(u)]) * w[:, None]
    b = (u**2 + v**2) * w
    (c0, c1, c2), *_ = np.linalg.lstsq(a, b, rcond=None)
    cx, cy = c0 / 2, c1 / 2
    r = math.sqrt(max(c2 + cx**2 + cy**2, 0.0))
    return float(cx + xm), float(cy + ym), r


def refine_circle(xs: np.ndarray, ys: np.ndarray, weights: np.ndarray,
                  circle: tuple[float, float, float], iters: int = 10
                  ) -> tuple[float, float, float]:
    """Geometric (orthogonal-distance) weighted least-squares circle by Gauss-Newton, started
    from `circle`: the algebraic fit is biased towards small radii when the points cover only
    part of the circle (a contact at the image border)."""
    cx, cy, r = circle
    sw = np.sqrt(np.asarray(weights, np.float64))
    for _ in range(iters):
        dx, dy = xs - cx, ys - cy
        d = np.maximum(np.hypot(dx, dy), 1e-9)
        res = (d - r) * sw
        jac = np.column_stack([-dx / d, -dy / d, -np.ones_like(d)]) * sw[:, None]
        step, *_ = np.linalg.lstsq(jac, -res, rcond=None)
        cx, cy, r = cx + step[0], cy + step[1], r + step[2]
        if float(np.abs(step).max()) < 1e-4:
            break
    return float(cx), float(cy), float(abs(r))


def ransac_circle(xs: np.ndarray, ys: np.ndarray, weights: np.ndarray, *,
                  r_range: tuple[float, float], tol: float, trials: int = 300, seed: int = 0
                  ) -> tuple[tuple[float, float, float], np.ndarray] | None:
    """The circle through three edge points that the most weight agrees with (within tol px),
    its radius inside r_range (the ball's size as a prior); then a weighted geometric fit to
    its inliers. Returns (circle, inlier mask), or None when no sample gives a circle in range.
    Deterministic (seeded): the same press gives the same circle."""
    n = xs.size
    if n < 3:
        return None
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, n, size=(trials, 3))
    p = np.stack([xs[idx], ys[idx]], axis=-1)  # (trials, 3, 2)
    # circumcentre of each triple
    ax, ay = p[:, 0, 0], p[:, 0, 1]
    bx, by = p[:, 1, 0], p[:, 1, 1]
    qx, qy = p[:, 2, 0], p[:, 2, 1]
    d = 2 * (ax * (by - qy) + bx * (qy - ay) + qx * (ay - by))
    ok = np.abs(d) > 1e-6
    d = np.where(ok, d, 1.0)
    a2, b2, q2 = ax**2 + ay**2, bx**2 + by**2, qx**2 + qy**2
    ux = (a2 * (by - qy) + b2 * (qy - ay) + q2 * (ay - by)) / d
    uy = (a2 * (qx - bx) + b2 * (ax - qx) + q2 * (bx - ax)) / d
    ur = np.hypot(ax - ux, ay - uy)
    ok &= (ur >= r_range[0]) & (ur <= r_range[1])
    if not ok.any():
        return None
    ux, uy, ur = ux[ok], uy[ok], ur[ok]
    res = np.abs(np.hypot(xs[None, :] - ux[:, None], ys[None, :] - uy[:, None]) - ur[:, None])
    score = ((res <= tol) * weights[None, :]).sum(axis=1)
    best = int(np.argmax(score))
    inl = res[best] <= tol
    if inl.sum() < 3:
        return None
    c = fit_circle(xs[inl], ys[inl], weights[inl])
    for _ in range(2):  # refit and re-collect the inliers of the refined circle
        c = refine_circle(xs[inl], ys[inl], weights[inl], c)
        inl = np.abs(np.hypot(xs - c[0], ys - c[1]) - c[2]) <= tol
        if inl.sum() < 3:
            return None
    if not r_range[0] - tol <= c[2] <= r_range[1] + tol:
        return None
    return c, inl


def _ray_edges(m: np.ndarray, cx: float, cy: float, r_max: float, sigma: float,
               n_rays: int = 180, step: float = 0.25
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sub-pixel edge points of the colour change along rays from (cx, cy), out to r_max:
    (xs, ys, weights).

    Along each ray the edge is where the change falls fastest just outside its peak (the
    colour changes most where the cap is steepest, at its rim; the blur moves the peak itself
    inwards), placed to a fraction of a sample by a parabola through the steepest drop and its
    neighbours. The weight is the drop relative to the ray's own peak above the median change
    (a ray along a dim side of the imprint counts as much as a bright one, a ray through
    noise little)."""
    import cv2

    radii = np.arange(step, r_max, step, dtype=np.float32)
    ang = np.linspace(0, 2 * np.pi, n_rays, endpoint=False, dtype=np.float32)
    mx = (cx + np.cos(ang)[:, None] * radii[None, :]).astype(np.float32)
    my = (cy + np.sin(ang)[:, None] * radii[None, :]).astype(np.float32)
    vals = cv2.remap(m, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=-1)
    inside = (mx >= 0) & (mx <= m.shape[1] - 1) & (my >= 0) & (my <= m.shape[0] - 1)
    rows = np.arange(n_rays)
    k = np.argmax(np.where(inside, vals, -np.inf), axis=1)
    drop = vals[:, :-1] - vals[:, 1:]  # drop[j]: between radii[j] and radii[j + 1]
    span = max(2, math.ceil((3 * sigma + 1) / step))
    j = np.minimum(np.arange(span)[None, :] + k[:, None], drop.shape[1] - 1)
    e = j[rows, np.argmax(drop[rows[:, None], j], axis=1)]
    e1 = np.clip(e, 1, drop.shape[1] - 2)
    a, b, c = drop[rows, e1 - 1], drop[rows, e1], drop[rows, e1 + 1]
    den = a - 2 * b + c
    frac = np.where(den < 0, 0.5 * (a - c) / np.where(den < 0, den, -1.0), 0.0)
    frac = np.clip(frac, -0.5, 0.5)
    r_edge = (radii[e1] + radii[e1 + 1]) / 2 + frac * step
    base = float(np.median(m))
    height = vals[rows, k] - base
    w = np.where(height > 0, b / np.maximum(height, 1e-6), 0.0)
    ok = (inside[rows, k] & (k > 0) & (e1 + 2 < radii.size)
          & inside[rows, np.minimum(e1 + 2, radii.size - 1)] & (w > 0) & (b > 0))
    ex = cx + np.cos(ang) * r_edge
    ey = cy + np.sin(ang) * r_edge
    return ex[ok].astype(np.float64), ey[ok].astype(np.float64), w[ok].astype(np.float64)


#: The plausible contact radius, as fractions of the ball radius in pixels: from a press about
#: a fiftieth of the ball radius deep (0.2 R: 0.04 mm for a 2 mm ball) to a little beyond the
#: equator (an imprint's edge can lie beyond it: Taxim's at 1.03-1.07 R; a circle above 1.3 R
#: fails its check anyway).
MIN_CONTACT_FRAC, MAX_CONTACT_FRAC = 0.2, 1.3


def radius_range(ball_px: float | None, min_radius_px: float, shape: tuple[int, int]
                 ) -> tuple[float, float]:
    """The contact radii (px) a ball of ball_px pixels can press: MIN_CONTACT_FRAC to
    MAX_CONTACT_FRAC of it (never below min_radius_px); without the ball, min_radius_px to the
    image's longer side."""
    if not ball_px:
        return float(min_radius_px), float(max(shape))
    return max(float(min_radius_px), MIN_CONTACT_FRAC * ball_px), MAX_CONTACT_FRAC * ball_px


def detect_circle(image: np.ndarray, background: np.ndarray, *, sigma: float | None = None,
                  min_radius_px: float = 3.0,
                  start: tuple[float, float, float] | None = None,
                  ball_px: float | None = None, restarts: bool = True
                  ) -> tuple[float, float, float] | None:
    """The contact circle (x, y, r) px of a ball press, or None when no contact is visible.

    The change map (`imprint.change_map`: blurred |image - background|, marker dots of the
    background and the press taken out) gives two starts: the disc over the plausible radii
    (`radius_range`, from the ball and the scale) that best covers the changed pixels
    (`imprint.disc_search`: the whole change, not its strongest part), and the convex hull of
    the strong-change component and the lobes beside it (`imprint_lobes`). From each, sub-pixel
    edge points along rays (`_ray_edges`) are fitted with a circle: RANSAC against rays that
    cross a shadow or a neighbouring change, radius within the plausible range, then a weighted
    geometric least-squares fit to the inliers, three times from the new centre. Of the two
    circles, the one with the most edge weight on it (`edge_support`) among those whose disc
    mostly shows a change is kept (the component's unless the other has RESTART_GAIN times its
    edge weight, or a rim that stands PICK_RING_GAIN times as far out: `_pick`). When neither
    start gives a circle whose rim stands RING_Z_MIN robust deviations out of the change around
    it (`imprint.ring_contrast`; a background taken under another light leaves a texture in
    which only the imprint's brightest lobe stands out, and a circle fitted to the texture does
    not pass), the disc search is run again at each of `imprint.TEXTURE_LEVELS`, and the circle
    whose rim stands out most replaces the first when its rim does pass. On a marker gel whose
    dots are wider than DOT_SIGMA_DIV times the blur, all this runs on a map blurred by the
    dots' diameter over DOT_SIGMA_DIV, and the circle is then settled on the usual map
    (`_settle`).
    ball_px: the ball radius in pixels (without it, any radius from
    min_radius_px). start: a first guess (x, y, r) instead of the two starts (what calibration
    retries with when the first circle fails its check). restarts: fit again from 8 starts
    around the circle and keep one that clearly more of the edge lies on (`_best_of_starts`;
    False: about 9 times faster).
    """
    if sigma is None:
        sigma = default_sigma(image.shape[:2])
        spec, _ = _background_dots(background)
        if spec is not None and spec.diameter_px / DOT_SIGMA_DIV > sigma:
            # a marker gel: the circle on a map blurred in proportion to its dots, settled on
            # the usual map, unless the usual map's own circle has a rim that stands out
            # PICK_RING_GAIN times as far there (a faint contact the blur spread below the
            # noise)
            wide = spec.diameter_px / DOT_SIGMA_DIV
            found = _search(change_map(image, background, wide, markers=True), wide,
                            min_radius_px, start, ball_px, restarts)
            m = change_map(image, background, sigma, markers=True)
            usual = _search(m, sigma, min_radius_px, start, ball_px, restarts)
            if found is None:
                return usual
            found = _settle(m, found, sigma)
            if usual is None:
                return found
            zu = ring_contrast(m, usual)
            return usual if zu > 0 and zu >= PICK_RING_GAIN * ring_contrast(m, found) else found
    return _search(change_map(image, background, sigma, markers=True), sigma, min_radius_px,
                   start, ball_px, restarts)


def _search(m: np.ndarray, sigma: float, min_radius_px: float,
            start: tuple[float, float, float] | None, ball_px: float | None, restarts: bool
            ) -> tuple[float, float, float] | None:
    """The contact circle on the change map `m` (blurred by sigma), or None: the starts, the
    pick, the restarts and the texture levels of `detect_circle`."""
    rr = radius_range(ball_px, min_radius_px, m.shape)
    if start is not None:
        found = _fit_rays(m, *start, sigma, rr)
    else:
        found = _pick(m, [_component_fit(m, sigma, min_radius_px, rr), _search_fit(m, sigma, rr)],
                      sigma)
    if restarts:
        found = _best_of_starts(m, found, sigma, min_radius_px, ball_px)
    if start is None and (found is None or ring_contrast(m, found) < RING_Z_MIN):
        # nothing, or a circle whose rim does not stand out (one fitted to a texture): the disc
        # search at the texture levels, the circle whose rim stands out most, kept only when it
        # does stand out
        best = RING_Z_MIN
        for level in TEXTURE_LEVELS:
            textured = _search_fit(m, sigma, rr, level)
            if restarts:
                textured = _best_of_starts(m, textured, sigma, min_radius_px, ball_px)
            z = -math.inf if textured is None else ring_contrast(m, textured)
            if z >= best:
                found, best = textured, z
    return found


#: On a marker gel the change map the circle is found on is blurred by at least the dots'
#: diameter over DOT_SIGMA_DIV: what a held or moved dot leaves at its rim (`imprint.change_map`)
#: is as wide as the dot is, so the same share of blur treats a grid alike at any resolution.
#: With the usual 1 px, the real sets with a real grid moved outward in each contact
#: (`benchmarks/circles_variants.py`) put circles up to 8.1 px (Taxim at 2x) and 4.8 px (DIGIT)
#: off the set's own detections; at 1/14, within 3.0 and 2.9 px. At 1/10 and 1/8 the blur
#: moved DIGIT's circles more (1/8: one 17 px off), and Taxim's dots, 10.6 px at its recorded
#: scale, keep its 1 px there.
DOT_SIGMA_DIV = 14.0

#: `_settle`: how far (share of the radius) the finer map's rim may lie from the blurred map's
#: circle, and how far its centre may move.
SETTLE_BAND, SETTLE_MOVE = 0.2, 0.15


def _settle(m: np.ndarray, circle: tuple[float, float, float], sigma: float
            ) -> tuple[float, float, float]:
    """A circle found on a blurrier map, settled on the finer map `m`: the radius is the
    weighted median of the edge points (`_ray_edges`) within SETTLE_BAND of it, then a geometric
    fit to the points on that radius, three times; a fit that moves the centre beyond
    SETTLE_MOVE of the radius (a dot's rim, not the contact's) keeps the centre. A blur moves
    a rim outward (a contact of 27 px by about 10 % under a blur of 2.8 px); the centre, where
    the rim is found all round, hardly moves."""
    cx, cy, r = circle
    x0, y0 = cx, cy
    for _ in range(3):
        px, py, wt = _ray_edges(m, cx, cy, 1.5 * r, sigma)
        rad = np.hypot(px - cx, py - cy)
        near = np.abs(rad - r) <= SETTLE_BAND * r
        if near.sum() < 12:
            break
        order = np.argsort(rad[near])
        cum = np.cumsum(wt[near][order])
        r = float(rad[near][order][np.searchsorted(cum, cum[-1] / 2)])
        on = np.abs(rad - r) <= ring_tol(r)
        if on.sum() < 12:
            break
        nx, ny, nr = refine_circle(px[on], py[on], wt[on], (cx, cy, r))
        if math.hypot(nx - x0, ny - y0) > SETTLE_MOVE * r or abs(nr - r) > SETTLE_BAND * r:
            break
        cx, cy, r = nx, ny, nr
    return cx, cy, r


#: A circle found only at a texture level (`imprint.TEXTURE_LEVELS`) is kept when the change
#: inside its rim stands this many robust deviations of the texture above the change outside
#: it (`imprint.ring_contrast`).
RING_Z_MIN = 3.5


def _search_fit(m: np.ndarray, sigma: float, rr: tuple[float, float], level: float = 5.0
                ) -> tuple[float, float, float] | None:
    """The circle fitted from the disc that best covers the change (`imprint.disc_search` at
    `level`, radii up to 1.6 times the plausible range: the change's support takes in the
    skirt)."""
    from .imprint import disc_search

    found = disc_search(m, (rr[0], 1.6 * rr[1]), level=level)
    if found is None or found[3] < 0.25 * math.pi * rr[0] ** 2:
        return None
    x, y, r, _ = found
    return _fit_rays(m, x, y, min(max(r, rr[0]), rr[1]), sigma, rr)


def _cover(m: np.ndarray, circle: tuple[float, float, float]) -> float:
    """The share of the circle's disc (inside the image) whose change stands above the noise."""
    from .imprint import changed

    x, y, r = circle
    h, w = m.shape
    yy, xx = np.ogrid[:h, :w]
    disc = (xx - x) ** 2 + (yy - y) ** 2 <= r * r
    return float(changed(m)[disc].mean()) if disc.any() else 0.0


def _pick(m: np.ndarray, found: list[tuple[float, float, float] | None], sigma: float
          ) -> tuple[float, float, float] | None:
    """Of the circles found from several starts, the first unless another has RESTART_GAIN
    times its edge weight (`edge_support`) or its rim stands PICK_RING_GAIN times as far out
    (`imprint.ring_contrast`), among those whose disc mostly shows a change (COVER_MIN; all of
    them when none does)."""
    cands = [c for c in found if c is not None]
    if not cands:
        return None
    covered = [c for c in cands if _cover(m, c) >= COVER_MIN] or cands
    best, score = covered[0], RESTART_GAIN * edge_support(m, covered[0], sigma)
    z = ring_contrast(m, best)
    for c in covered[1:]:
        sc, zc = edge_support(m, c, sigma), ring_contrast(m, c)
        if sc > score or (zc > 0 and zc >= PICK_RING_GAIN * z):  # z <= 0: no rim at all
            best, score, z = c, sc, zc
    return best


#: A later start's circle replaces the first when its rim stands this many times as far out of
#: the change around it. A circle on one bright lobe of a deep press (its outside still the
#: contact) keeps as much edge support as the contact's circle but stands out a quarter as
#: much (a simulated press under four side lights: 15.5 against 56 robust deviations); on 342
#: other simulated presses of every light layout the two starts' contrasts are 0.72-1.02 times
#: each other, and no circle of the real press sets or their variants changes.
PICK_RING_GAIN = 2.0


def _component_fit(m: np.ndarray, sigma: float, min_radius_px: float, rr: tuple[float, float]
                   ) -> tuple[float, float, float] | None:
    """The circle fitted from the strong-change components of the change map `m` (the convex
    hull of the imprint's lobes, `imprint_lobes`: its centroid and equal-area radius as the
    start), or None without one."""
    import cv2

    comp = imprint_lobes(m, min_radius_px)
    if comp is None:
        return None
    # The flat top of the cap and the side facing away from the lights change little, so the
    # lobes can form a ring, a crescent or two halves: their convex hull stands for the contact.
    pts = np.column_stack(np.nonzero(comp)[::-1]).astype(np.int32)
    hull = np.zeros(m.shape, np.uint8)
    cv2.fillConvexPoly(hull, cv2.convexHull(pts), 1)
    area = int(hull.sum())
    ys, xs = np.nonzero(hull)
    r0 = min(max(math.sqrt(area / math.pi), rr[0]), rr[1])
    return _fit_rays(m, float(xs.mean()), float(ys.mean()), r0, sigma, rr)


#: A strong-change component joins the largest one as a lobe of the same imprint when it has at
#: least LOBE_MIN_FRAC of its area and lies within LOBE_GAP times its equal-area radius of it.
LOBE_MIN_FRAC, LOBE_GAP = 0.25, 1.0


def imprint_lobes(m: np.ndarray, min_radius_px: float) -> np.ndarray | None:
    """The pixels of the imprint's strong change (bool H x W): the largest component above the
    strict threshold and every other one of at least LOBE_MIN_FRAC of its area within LOBE_GAP
    of its equal-area radius of it; None when the largest is smaller than a disc of
    min_radius_px.

    Where a sensor's lights lie along one axis the change is near zero along the line through
    the apex across it (the slope along that axis is zero there), so the strong change can come
    in two halves with a dark band between them, and the larger half alone gives a small circle
    on one side (DIGIT press 0008: r 6.8 px of about 25). A change far from the imprint, or a
    small one beside it, is not joined."""
    import cv2

    strict, _ = _change_threshold(m)
    n, lab, stats, _ = cv2.connectedComponentsWithStats((m > strict).astype(np.uint8),
                                                        connectivity=8)
    if n <= 1:
        return None
    area = stats[:, cv2.CC_STAT_AREA]
    best = 1 + int(np.argmax(area[1:]))
    if area[best] < math.pi * min_radius_px**2:
        return None
    others = [i for i in range(1, n) if i != best and area[i] >= LOBE_MIN_FRAC * area[best]]
    if not others:
        return lab == best
    gap = cv2.distanceTransform((lab != best).astype(np.uint8), cv2.DIST_L2, 5)
    reach = LOBE_GAP * math.sqrt(area[best] / math.pi)
    keep = [best] + [i for i in others if float(gap[lab == i].min()) <= reach]
    return np.isin(lab, keep)


#: Restarts around a found circle: 8 starts this fraction of its radius away, and the gain in
#: edge support a restart's circle needs to replace it (see `_best_of_starts`).
RESTART_FRAC, RESTART_GAIN = 0.15, 1.2


def ring_tol(r: float) -> float:
    """How far (px) an edge point may lie from a circle of radius r and still be on it: the
    RANSAC inlier tolerance of `_fit_rays`, and what `edge_support` counts."""
    return max(1.0, 0.06 * r)


def edge_support(m: np.ndarray, circle: tuple[float, float, float], sigma: float) -> float:
    """The weight of the edge points, along rays from the circle's centre, that lie on it
    (within the RANSAC tolerance): how much of the imprint's edge the circle explains."""
    cx, cy, r = circle
    px, py, wt = _ray_edges(m, cx, cy, 1.5 * r, sigma)
    on = np.abs(np.hypot(px - cx, py - cy) - r) <= ring_tol(r)
    return float(wt[on].sum())


def _best_of_starts(m: np.ndarray, found: tuple[float, float, float] | None, sigma: float,
                    min_radius_px: float, ball_px: float | None
                    ) -> tuple[float, float, float] | None:
    """The circle, of `found` and those fitted again from 8 starts around it (RESTART_FRAC of
    its radius away), that the most edge weight lies on (`edge_support`); a restart replaces
    `found` only with RESTART_GAIN times its support (gains of a few per cent are the rays
    sampling other pixels). Where a bright lobe inside the contact gives a second, inner ring
    of edge points on one side, the fit can settle on a circle through parts of both rings; a
    restart settles on the full outer ring instead."""
    if found is None:
        return None
    best, score = found, RESTART_GAIN * edge_support(m, found, sigma)
    d = RESTART_FRAC * found[2]
    rr = radius_range(ball_px, min_radius_px, m.shape)
    for ang in np.arange(8) * (np.pi / 4):
        c = _fit_rays(m, found[0] + d * math.cos(ang), found[1] + d * math.sin(ang), found[2],
                      sigma, rr)
        if c is not None:
            sc = edge_support(m, c, sigma)
            if sc > score:
                best, score = c, sc
    return best


#: In RANSAC a ray's edge weight counts at most RAY_WEIGHT_CAP times the median ray's: a ray
#: whose change peaks low and then drops at once (where two lights cancel, or a lit skirt's
#: outer fall on a diagonal) otherwise outweighs two or three rays along the rim. Under four
#: side lights (`sides4`, contacts of 0.5-0.95 ball radii, seeds 0 and 1) it takes the
#: presses beyond 3 px from 14 to 9 of 128, and on the drawn portrait gel without markers the
#: worst from 8.6 to 0.5 px (held-out depth, detected / exact circles, 1.31x to 1.00x); the real
#: sets' circles move a median 0.00 (Taxim) and 0.06 px (DIGIT), at most 0.6 px (1.8 px under
#: camera noise). At 1 (every ray counted alike) a drawn landscape press was mended too, but
#: DIGIT press 0012 under camera noise or another exposure jumped from r 26 to 23 px, between
#: two rings; 1.5 is the strongest cap of 1, 1.5 and 2 that keeps every DIGIT circle of those
#: two variants within 1.2 px of the uncapped one. RANSAC alone: the pick and the restarts
#: weigh the rays as found.
RAY_WEIGHT_CAP = 1.5


def _fit_rays(m: np.ndarray, cx: float, cy: float, r0: float, sigma: float,
              rr: tuple[float, float]) -> tuple[float, float, float] | None:
    """Fit the circle, radius within rr, to the edges found along rays from (cx, cy), three
    times, each ray's weight capped at RAY_WEIGHT_CAP times the median (see detect_circle)."""
    h, w = m.shape
    r = r0
    min_radius_px, r_hi = rr
    for _ in range(3):
        px, py, wt = _ray_edges(m, cx, cy, 1.5 * max(r0, r), sigma)
        if px.size < 12:
            return None
        wt = np.minimum(wt, RAY_WEIGHT_CAP * float(np.median(wt)))
        found = ransac_circle(px, py, wt, r_range=(min_radius_px, r_hi), tol=ring_tol(r))
        if found is None or found[1].sum() < 12:
            return None
        cx, cy, r = found[0]
    if not (min_radius_px <= r <= r_hi and 0 <= cx < w and 0 <= cy < h):
        return None
    return cx, cy, r


# -- self-check of a contact circle ------------------------------------------------------------

#: A circle is doubted when its radius is outside [SUPPORT_LOW, SUPPORT_HIGH] times the radius
#: of the area whose colour change stands above the noise (measured: good circles at 0.50-0.63
#: of it on DIGIT presses, which have a wide skirt, 0.72-1.22 on Taxim's GelSight, its labels up
#: to 1.32; a circle on one lobe of DIGIT 0008, its first detection before `imprint_lobes`,
#: at 0.17), or when less than COVER_DOUBT of its disc shows a change (a centre off the imprint).
SUPPORT_LOW, SUPPORT_HIGH = 0.4, 1.6
COVER_MIN = 0.5
#: The check's own floor on that cover: lower than the detector's pick (COVER_MIN), since a faint
#: press's true circle can show less. A circle shifted by a whole radius on the real presses
#: still covers 0.88-1.0 (the change reaches into the skirt), so the cover only tells a circle
#: off the imprint altogether (0 % on circles fitted to another light's texture); the true
#: circles of DIGIT's two presses under another light cover 0.41-0.60 under a real marker grid
#: (`benchmarks/circles_variants.py`), and at 0.5 the check dropped one of them in 6 of 35
#: variants and combinations.
COVER_DOUBT = 0.4


def _change_threshold(m: np.ndarray) -> tuple[float, float]:
    """(strict, loose) thresholds of a change map: clearly changed, and above the noise."""
    med = float(np.median(m))
    mad = float(np.median(np.abs(m - med))) * 1.4826 + 1e-3
    peak = float(np.percentile(m, 99.99))
    return (max(med + 6 * mad, med + 0.2 * (peak - med), med + 3.0),
            max(med + 4 * mad, med + 0.05 * (peak - med), med + 2.0))


def default_sigma(shape: tuple[int, int]) -> float:
    """The smoothing (px) of the change map for an image of this (H, W): 1 px per 240 of the
    shorter side, at least 1."""
    return max(1.0, min(shape) / 240)


def _largest_change(m: np.ndarray, loose: float) -> tuple[float, float, float] | None:
    """(x, y, r) of the largest region of the change map `m` above `loose` (r: the radius of a
    disc of its area), or None if there is none."""
    import cv2

    n, _, stats, cent = cv2.connectedComponentsWithStats((m > loose).astype(np.uint8),
                                                         connectivity=8)
    if n <= 1:
        return None
    best = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    area = float(stats[best, cv2.CC_STAT_AREA])
    return float(cent[best, 0]), float(cent[best, 1]), math.sqrt(area / math.pi)


def _hull_of_largest(mask: np.ndarray) -> np.ndarray:
    """The mask (bool H x W) with the convex hull of its largest component filled in."""
    import cv2

    n, lab, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    if n <= 1:
        return mask
    best = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    pts = np.column_stack(np.nonzero(lab == best)[::-1]).astype(np.int32)
    out = mask.astype(np.uint8)
    cv2.fillConvexPoly(out, cv2.convexHull(pts), 1)
    return out.astype(bool)


def change_support(image: np.ndarray, background: np.ndarray, sigma: float | None = None,
                   m: np.ndarray | None = None) -> tuple[float, float, float] | None:
    """The imprint as the colour change shows it: (x, y, r) of the largest region whose change
    stands above the noise (r: the radius of a disc of its area), or None if there is none.
    m: the change map at sigma when the caller has it (markers taken out)."""
    if m is None:
        sigma = default_sigma(image.shape[:2]) if sigma is None else sigma
        m = change_map(image, background, sigma, markers=True)
    return _largest_change(m, _change_threshold(m)[1])


def circle_doubts(circle: tuple[float, float, float], image: np.ndarray, background: np.ndarray,
                  ball_px: float, m: np.ndarray | None = None) -> list[str]:
    """Why a contact circle (x, y, r px) is implausible for this press, or [] when it is not:
    larger than the ball, a radius far from what the colour change supports, a disc that
    mostly shows no change (centre off the imprint), a centre off the image, a stronger change
    elsewhere (`_stronger_outside`). m: the press's change map when the caller has it
    (`change_map` at `default_sigma`, markers taken out), so it is not built again."""
    x, y, r = circle
    h, w = image.shape[:2]
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(r)) or r <= 0:
        return [f"circle ({x}, {y}, {r}) is not a circle"]
    out = []
    if not (0 <= x < w and 0 <= y < h):
        out.append(f"centre ({x:.1f}, {y:.1f}) lies outside the {h}x{w} image")
    if r > 1.3 * ball_px:
        out.append(f"radius {r:.1f} px is larger than the ball ({ball_px:.1f} px)")
    if m is None:
        m = change_map(image, background, default_sigma((h, w)), markers=True)
    _, loose = _change_threshold(m)
    sup = _largest_change(m, loose)  # what change_support gives, from the same map
    if sup is None:
        return [*out, "no visible colour change"]
    sr = sup[2]
    # Light that shows the slope's size only (near-uniform light) leaves the shallow cap's top
    # unchanged: a ring, of which a weak press shows a crescent above the noise. What the
    # largest change encloses (its convex hull, as the detector's start takes it) counts as
    # changed against a too-large circle and for the cover, never against a too-small one.
    changed = _hull_of_largest(m > loose)
    sr_hull = max(sr, math.sqrt(float(changed.sum()) / math.pi))
    if not SUPPORT_LOW * sr <= r <= SUPPORT_HIGH * sr_hull:
        shown = sr if r < SUPPORT_LOW * sr else sr_hull
        out.append(f"radius {r:.1f} px, but the colour change covers about {shown:.1f} px")
    yy, xx = np.ogrid[:h, :w]
    d2 = (xx - x) ** 2 + (yy - y) ** 2  # squared distance to the centre, for both tests below
    disc = d2 <= r * r
    cover = float(changed[disc].mean()) if disc.any() else 0.0
    if cover < COVER_DOUBT:
        out.append(f"only {cover:.0%} of the circle shows a colour change (centre off the "
                   "imprint)")
    if _stronger_outside(m, r, d2):
        out.append("a stronger colour change lies outside the circle (the imprint is elsewhere)")
    return out


#: `_stronger_outside`: the share of the disc's area that a change beyond OUTSIDE_FROM radii
#: must cover to count, and the top share of the change within INSIDE_TO radii it is compared
#: with.
OUTSIDE_SHARE, OUTSIDE_FROM, INSIDE_TO, INSIDE_TOP = 0.05, 1.5, 1.15, 0.01


def _stronger_outside(m: np.ndarray, r: float, d2: np.ndarray) -> bool:
    """Whether the change map shows, beyond OUTSIDE_FROM radii of the circle and over at least
    OUTSIDE_SHARE of its disc's area, a change stronger than the circle's own strongest (its
    top INSIDE_TOP within INSIDE_TO radii), both above the median change: a circle that missed
    the imprint. Measured (`benchmarks/circles_variants.py`, both real sets and 23 variants):
    the circle's own change is 1.67 times the other or more on every labelled and every used
    detected circle but one 7 px off (1.17); 0.54 on a contact cut by the frame's border whose
    red lobe clips at 255, where the circle was found 29 px off around the clipped area (before
    the change map restored clipped channels, `imprint.restore_clipped`). Costs
    2.1 ms at 320x240 (`circle_doubts` 19 -> 22 ms a press, best of 5; 2 cores, AMD EPYC).
    r: the circle's radius; d2: each pixel's squared distance to its centre (`circle_doubts`'s)."""
    inside, outside = m[d2 <= (INSIDE_TO * r) ** 2], m[d2 >= (OUTSIDE_FROM * r) ** 2]
    k = max(1, int(OUTSIDE_SHARE * math.pi * r * r))
    if inside.size == 0 or outside.size < k:
        return False
    med = float(np.median(m))
    own = float(np.quantile(inside, 1 - INSIDE_TOP)) - med
    other = float(np.partition(outside, outside.size - k)[outside.size - k]) - med
    return other > max(own, 0.0)
