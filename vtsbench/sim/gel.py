"""Elastic gel contact: the rigid overlap of object and gel, conformed finely and spread widely.

With P the rigid overlap (how far the object would sink into an undeformed gel), the gel
surface indentation is D = max(G_fine * P, G_spread * P): G_fine (sigma 0.03 mm) limits how
finely the coating follows the object, G_spread (sigma 0.4 mm, computed on a grid reduced by
an integer factor) pulls the surrounding gel down into a skirt and bridges narrow valleys.
The gel touches the object where P > 0 and the fine term is the larger one.
"""

from __future__ import annotations

import math

import numpy as np

SIGMA_FINE_MM = 0.03
SIGMA_SPREAD_MM = 0.4
#: Target blur sigma (coarse pixels) on the reduced grid of the spread term.
_COARSE_SIGMA_PX = 3.0


def _ksize(sigma_px: float) -> int:
    """Odd Gaussian kernel size covering +-3 sigma."""
    return 2 * math.ceil(3.0 * sigma_px) + 1


def spread_factor(mm_per_px: float) -> int:
    """Integer reduction of the grid on which the spread term is blurred."""
    return max(1, int(SIGMA_SPREAD_MM / mm_per_px / _COARSE_SIGMA_PX))


def margin_px(mm_per_px: float, spread: bool = True) -> int:
    """How many pixels beyond the rigid overlap the indentation can reach (a safe bound)."""
    fine = _ksize(SIGMA_FINE_MM / mm_per_px) // 2
    if not spread:
        return fine + 2
    f = spread_factor(mm_per_px)
    coarse = _ksize(SIGMA_SPREAD_MM / mm_per_px / f) // 2
    return max(fine, f * (coarse + 2)) + 2


def _blur(a: np.ndarray, sigma_px: float) -> np.ndarray:
    """Gaussian blur with zero outside the box (a copy when the blur is sub-pixel)."""
    import cv2

    if sigma_px < 0.25:  # narrower than a pixel: a no-op at this sampling
        return a.copy()
    k = _ksize(sigma_px)
    return cv2.GaussianBlur(a, (k, k), sigmaX=sigma_px, sigmaY=sigma_px,
                            borderType=cv2.BORDER_CONSTANT)


def solve(overlap: np.ndarray, mm_per_px: float,
          spread: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Gel indentation D (mm, float64) and contact mask of a rigid-overlap box.

    The box's height and width must be multiples of spread_factor(mm_per_px), and the box must
    hold margin_px(mm_per_px) pixels of zero overlap around the positive part.
    """
    import cv2

    fine = _blur(overlap, SIGMA_FINE_MM / mm_per_px)
    if not spread:
        return fine, overlap > 0.0
    f = spread_factor(mm_per_px)
    h, w = overlap.shape
    if h % f or w % f:
        raise ValueError(f"overlap box {h}x{w} is not a multiple of the spread factor {f}")
    small = overlap if f == 1 else cv2.resize(overlap, (w // f, h // f),
                                              interpolation=cv2.INTER_AREA)
    small = _blur(small, SIGMA_SPREAD_MM / mm_per_px / f)
    wide = small if f == 1 else cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)
    contact = (overlap > 0.0) & (fine >= wide)
    np.maximum(fine, wide, out=fine)
    return fine, contact
