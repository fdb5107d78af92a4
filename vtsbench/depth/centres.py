"""Contact centres that agree with the sensor's own colour response: a check of circles (labelled
or detected) that needs neither of them to be right.

A calibration maps colour to the gel's slope; a press of a ball of radius R centred at (xc, yc)
has the slopes p = -(x - xc) / z, q = -(y - yc) / z inside its contact (z = sqrt(R^2 - rho^2)).
`sphere_centre` fits (xc, yc) to a press's predicted slopes well inside the contact.
`consistent_centres` alternates the two: calibrations fitted on all presses but a fold (the
press itself never trains the calibration it is fitted with), then every press's centre fitted
to its predicted slopes, for a few rounds. A circle off its imprint by a few pixels trains
slopes that the other presses contradict, so its centre moves to where the colour says the
apex is; on simulated presses with known centres, labels moved by 3-4 px come back to within
about a pixel (tests/depth/test_centres.py).

It is a check, not a detector: it needs a start within a few pixels and MIN_PRESSES presses,
and a shift shared by every circle is only weakly fixed (the mapping can partly absorb it).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

#: Presses needed: on simulated presses with known centres (120x160), 30 or 40 presses bring
#: labels moved by 3.5-3.6 px back to within 1.2 px in 4 rounds, while 10 presses drift off (the
#: calibrations then follow the wrong centres as much as they correct them).
MIN_PRESSES = 30
#: Fraction of the contact radius inside which the slopes are fitted (the rim is the least sure).
INNER = 0.75


def sphere_centre(gradients: np.ndarray, x: float, y: float, r_px: float, ball_radius_mm: float,
                  mm_per_px: tuple[float, float]) -> tuple[float, float]:
    """The centre (px) of the ball's slopes that best fits predicted slopes (H x W x 2) inside
    INNER r_px of the start (x, y): robust (soft L1) least squares over the centre."""
    from scipy.optimize import least_squares

    h, w = gradients.shape[:2]
    mx, my = mm_per_px
    rad = INNER * r_px
    x0, x1 = max(0, math.floor(x - rad)), min(w, math.ceil(x + rad) + 1)
    y0, y1 = max(0, math.floor(y - rad)), min(h, math.ceil(y + rad) + 1)
    if x1 <= x0 or y1 <= y0:
        return float(x), float(y)
    yy, xx = np.mgrid[y0:y1, x0:x1]
    sel = np.hypot(xx - x, yy - y) <= rad
    if sel.sum() < 8:
        return float(x), float(y)
    xs, ys = xx[sel].astype(np.float64), yy[sel].astype(np.float64)
    p, q = gradients[y0:y1, x0:x1, 0][sel], gradients[y0:y1, x0:x1, 1][sel]
    big_r2 = float(ball_radius_mm) ** 2
    floor = 0.09 * big_r2  # z at least 0.3 R: finite slopes if the start is far off

    def residual(c: np.ndarray) -> np.ndarray:
        dx, dy = (xs - c[0]) * mx, (ys - c[1]) * my
        z = np.sqrt(np.maximum(big_r2 - dx**2 - dy**2, floor))
        return np.concatenate([p + dx / z, q + dy / z])

    fit = least_squares(residual, x0=np.array([x, y], np.float64), loss="soft_l1", f_scale=0.2)
    cx, cy = (float(v) for v in fit.x)
    if not (math.isfinite(cx) and math.isfinite(cy)):
        return float(x), float(y)
    return cx, cy


def consistent_centres(presses: list[Any], background: np.ndarray, setup: dict[str, Any], *,
                       method: str = "poly", folds: int = 5, rounds: int = 4, seed: int = 0,
                       options: dict[str, Any] | None = None) -> list[tuple[float, float]]:
    """Per press (in order), the centre (x, y) px after `rounds` of: fit a calibration on the
    other folds' presses with their current centres, fit each held-out press's centre to its
    predicted slopes (`sphere_centre`). presses and setup as `calibration.load_presses` gives
    them; each press's radius stays as it is."""
    from .calibration import BLUR_PX, fit_calibration
    from .sphere import Rim

    n = len(presses)
    if n < MIN_PRESSES:
        raise ValueError(f"consistent centres need at least {MIN_PRESSES} presses, got {n}")
    fold = np.arange(n) % folds
    current = list(presses)
    for _ in range(rounds):
        moved = list(current)
        for k in range(folds):
            train = [p for i, p in enumerate(current) if fold[i] != k]
            cal, _ = fit_calibration(train, background, setup, method, rim=Rim(),
                                     blur_px=BLUR_PX, rng=np.random.default_rng(seed),
                                     options=options)
            for i in np.nonzero(fold == k)[0]:
                p = current[i]
                cx, cy = sphere_centre(cal.gradients(p.image), p.x, p.y, p.r,
                                       p.ball_radius_mm, setup["mm_per_px"])
                moved[i] = replace(p, x=cx, y=cy)
        current = moved
    return [(p.x, p.y) for p in current]


def symmetric_centre(m: np.ndarray, x: float, y: float, radius: float, span: float = 8.0
                     ) -> tuple[float, float]:
    """The point within `span` px of (x, y) about which the change map `m` (H x W) is most
    point-symmetric over a disc of `radius` px: the centre that minimises the mean squared
    difference between m(c + u) and m(c - u).

    A check of a circle's centre that needs neither a label nor the edge detector: to first
    order the colour change follows the slope, which is odd about the apex, so its size is
    even about it, whatever the lights' directions and even where the change has no edge (a
    dark band through the apex). Unevenly bright lobes and light that varies across the gel
    make it a coarse check: on Taxim's presses it lies 0.5-2.9 px from the consistent centres
    (docs/depth.md). A 1 px grid, then a 0.25 px one around the best point."""
    import cv2

    g = np.arange(-math.ceil(radius), math.ceil(radius) + 1, dtype=np.float32)
    u, v = np.meshgrid(g, g)  # a square map (OpenCV's remap takes under 32767 per side)
    disc = np.hypot(u, v) <= radius

    def asymmetry(cx: float, cy: float) -> float:
        a = cv2.remap(m, np.float32(cx) + u, np.float32(cy) + v, cv2.INTER_LINEAR,
                      borderMode=cv2.BORDER_REFLECT)
        b = cv2.remap(m, np.float32(cx) - u, np.float32(cy) - v, cv2.INTER_LINEAR,
                      borderMode=cv2.BORDER_REFLECT)
        return float(np.mean((a[disc] - b[disc]) ** 2))

    best = (x, y)
    for step, reach in ((1.0, span), (0.25, 1.0)):
        offs = np.arange(-reach, reach + 1e-9, step)
        cx0, cy0 = best
        best = min(((cx0 + dx, cy0 + dy) for dx in offs for dy in offs),
                   key=lambda c: asymmetry(*c))
    return float(best[0]), float(best[1])
