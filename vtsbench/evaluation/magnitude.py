"""Accuracy by slip magnitude: direction accuracy per slip-distance bin, state accuracy per state.

The slip distance of a sequence is the length of its labelled motion (the index's
`motion_dx_mm`, `motion_dy_mm`), in mm, and in pixels at the model's input: mm over the sample's
mm per pixel (x and y apart), times the input scale the submission states (model-input pixels
per sensor pixel, `input_scale_xy` in its metadata; 1 when absent). Bins are half-open
[lo, hi) in mm; a sample whose motion is unknown (NaN) counts apart. Pure numpy apart from the
index read (through `vtsbench.load`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from itertools import pairwise
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from ..dataset.read.loader import VtsDataset

#: Bin edges in mm (half-open [lo, hi)); the simulator's slips run from 0.08 to 1.5 mm, the
#: slip threshold is 0.05 mm.
MAGNITUDE_EDGES_MM: tuple[float, ...] = (0.0, 0.1, 0.2, 0.4, 0.8, math.inf)


def slip_motion(dataset: str | Path | VtsDataset, ids: Sequence[str]) -> dict[str, np.ndarray]:
    """Per sample id (in the given order): motion dx, dy (mm, image frame) and mm per pixel x, y
    from the slip index of a dataset (a folder, a URL or one `vtsbench.load` loaded); NaN where
    unknown."""
    from .submission import open_dataset

    cols = ["sample_id", "motion_dx_mm", "motion_dy_mm", "mm_per_px_x", "mm_per_px_y"]
    table = open_dataset(dataset).slip.index.select(cols).to_pydict()
    pos = {s: i for i, s in enumerate(table["sample_id"])}

    def col(name: str) -> np.ndarray:
        vals = table[name]
        return np.array([math.nan if (i := pos.get(s)) is None or vals[i] is None else vals[i]
                         for s in ids], dtype=np.float64)

    return {"dx_mm": col("motion_dx_mm"), "dy_mm": col("motion_dy_mm"),
            "mm_per_px_x": col("mm_per_px_x"), "mm_per_px_y": col("mm_per_px_y")}


def distances(motion: dict[str, np.ndarray],
              input_scale_xy: Sequence[float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Slip distance per sample in mm and in pixels at the model's input (NaN where unknown)."""
    dx, dy = motion["dx_mm"], motion["dy_mm"]
    sx, sy = (1.0, 1.0) if input_scale_xy is None else (float(input_scale_xy[0]),
                                                         float(input_scale_xy[1]))
    with np.errstate(invalid="ignore", divide="ignore"):
        px = np.hypot(dx / motion["mm_per_px_x"] * sx, dy / motion["mm_per_px_y"] * sy)
    return np.hypot(dx, dy), px


def _edge(v: float) -> float | None:
    return None if not math.isfinite(v) else float(v)


def by_magnitude(correct: Any, mm: Any, px: Any,
                 edges: Sequence[float] = MAGNITUDE_EDGES_MM) -> dict[str, Any]:
    """Accuracy per slip-distance bin [edges[i], edges[i+1]) in mm, with the bin's pixel range
    at the model's input (min, median, max of its samples). Empty bins: n 0, accuracy null.
    `correct` holds one bool per sample; NaN distances go to `n_unknown`."""
    ok = np.asarray(correct, dtype=bool).ravel()
    mm, px = np.asarray(mm, dtype=float).ravel(), np.asarray(px, dtype=float).ravel()
    if not (ok.shape == mm.shape == px.shape):
        raise ValueError(f"{ok.size} results, {mm.size} distances in mm, {px.size} in px")
    e = np.asarray(edges, dtype=float)
    if e.size < 2 or np.any(np.diff(e) <= 0) or np.isnan(e).any():
        raise ValueError("bin edges must be at least two increasing numbers")
    known = np.isfinite(mm)
    bins = []
    for lo, hi in pairwise(e):
        m = known & (mm >= lo) & (mm < hi)
        n = int(m.sum())
        p = px[m][np.isfinite(px[m])]
        bins.append({"lo_mm": _edge(lo), "hi_mm": _edge(hi), "n": n,
                     "correct": int(ok[m].sum()),
                     "accuracy": float(ok[m].mean()) if n else None,
                     "px_min": float(p.min()) if p.size else None,
                     "px_median": float(np.median(p)) if p.size else None,
                     "px_max": float(p.max()) if p.size else None})
    outside = known & ((mm < e[0]) | (mm >= e[-1]))
    return {"edges_mm": [_edge(v) for v in e], "bins": bins,
            "n_unknown": int((~known).sum()), "n_outside": int(outside.sum())}


def per_state(state_true: Any, state_pred: Any, names: Sequence[str]) -> dict[str, Any]:
    """State accuracy (recall) per true state: {name: {n, accuracy}} (accuracy null if n is 0)."""
    t, p = np.asarray(state_true).ravel(), np.asarray(state_pred).ravel()
    out = {}
    for k, name in enumerate(names):
        m = t == k
        n = int(m.sum())
        out[name] = {"n": n, "accuracy": float((p[m] == k).mean()) if n else None}
    return out
