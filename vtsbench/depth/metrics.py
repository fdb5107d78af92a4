"""Depth-map errors in mm: plane-aligned RMSE (the paper's), contact-region RMSE, peak error.

All take a predicted and a true depth map (H, W) in mm, positive into the gel, and an optional
boolean region; they work in float64 whatever the inputs, and need neither torch nor a dataset.

    e = pred - true over the region R (all pixels when no region is given)
    plane-aligned RMSE = min over (a, b, c) of sqrt(mean_R (e - (a + b x + c y))^2)
    contact RMSE       = sqrt(mean_C e^2), C the true contact region
    peak depth error   = max_R pred - max_R true   (signed: positive means too deep)
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np


def _region(true: np.ndarray, region: np.ndarray | None) -> np.ndarray:
    if region is None:
        return np.ones(true.shape, bool)
    region = np.asarray(region, bool)
    if region.shape != true.shape:
        raise ValueError(f"region shape {region.shape} differs from depth shape {true.shape}")
    return region


def _check(pred: np.ndarray, true: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pred, true = np.asarray(pred, np.float64), np.asarray(true, np.float64)
    if pred.shape != true.shape or pred.ndim != 2:
        raise ValueError(f"expected two (H, W) maps of one shape, got {pred.shape} and "
                         f"{true.shape}")
    return pred, true


def plane_aligned_rmse(pred: np.ndarray, true: np.ndarray,
                       region: np.ndarray | None = None) -> float:
    """RMSE after removing the least-squares plane of the error over the region (mm).

    Removes a constant offset and a tilt, which a press stage's misalignment would cause, so
    what is left is the error in shape. NaN for an empty region.
    """
    pred, true = _check(pred, true)
    r = _region(true, region)
    n = int(r.sum())
    if n == 0:
        return math.nan
    ys, xs = np.nonzero(r)
    e = (pred - true)[r]
    if n < 3:
        return 0.0
    # Centre the coordinates so the 3x3 normal equations stay well conditioned.
    a = np.column_stack([np.ones(n), xs - xs.mean(), ys - ys.mean()])
    coef, *_ = np.linalg.lstsq(a, e, rcond=None)
    res = e - a @ coef
    return float(np.sqrt(np.mean(res**2)))


def rmse(pred: np.ndarray, true: np.ndarray, region: np.ndarray | None = None) -> float:
    """Plain RMSE over the region (mm); NaN for an empty region."""
    pred, true = _check(pred, true)
    r = _region(true, region)
    if not r.any():
        return math.nan
    return float(np.sqrt(np.mean((pred - true)[r] ** 2)))


def peak_depth_error(pred: np.ndarray, true: np.ndarray,
                     region: np.ndarray | None = None) -> float:
    """Deepest predicted minus deepest true indentation over the region (mm, signed)."""
    pred, true = _check(pred, true)
    r = _region(true, region)
    if not r.any():
        return math.nan
    return float(pred[r].max() - true[r].max())


@dataclass(frozen=True)
class DepthErrors:
    """The three figures for one depth map, in mm."""

    plane_aligned_rmse_mm: float
    contact_rmse_mm: float
    peak_depth_error_mm: float

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


def depth_errors(pred: np.ndarray, true: np.ndarray, contact: np.ndarray,
                 region: np.ndarray | None = None) -> DepthErrors:
    """All three: plane-aligned RMSE over region (default: contact), contact RMSE, peak error."""
    region = contact if region is None else region
    return DepthErrors(plane_aligned_rmse(pred, true, region), rmse(pred, true, contact),
                       peak_depth_error(pred, true, contact))
