"""Benchmark metrics, pure numpy (no torch, no dataset on disk).

Labels are class indices 0..K-1 in a fixed order (states: static, press, slip; directions 0..7
counter-clockwise from image right; objects: the dataset's sorted object names). Confusion
matrices have rows = true class, columns = predicted class, in that order.

Edge cases, the same everywhere:
- empty input: every rate is NaN (written as null in JSON), counts are 0;
- a class never present in the truth: left out of balanced accuracy (as scikit-learn) and its
  recall is NaN; if it is predicted, its F1 is 0 and it counts in macro-F1;
- a class never predicted: precision NaN, F1 0 if it is present;
- a class neither present nor predicted: left out of macro-F1, its F1 is NaN;
- a single class: the metrics are computed as defined (balanced accuracy = its recall);
- one sample: the bootstrap interval is [value, value];
- no direction errors: the adjacent share of errors is NaN.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..labels import BIN_DEG, N_DIRECTIONS

#: Version of the metric definitions; a change makes stored leaderboard entries stale.
METRIC_VERSION = "1.0"
BOOTSTRAP = 1000
NAN = float("nan")


def _labels(y: Any, n_classes: int, what: str) -> np.ndarray:
    a = np.asarray(y, dtype=np.int64).ravel()
    if a.size and (a.min() < 0 or a.max() >= n_classes):
        raise ValueError(f"{what} labels must lie in 0..{n_classes - 1}")
    return a


def _pair(y_true: Any, y_pred: Any, n_classes: int) -> tuple[np.ndarray, np.ndarray]:
    t, p = _labels(y_true, n_classes, "true"), _labels(y_pred, n_classes, "predicted")
    if t.shape != p.shape:
        raise ValueError(f"{t.size} true labels but {p.size} predictions")
    return t, p


def confusion_matrix(y_true: Any, y_pred: Any, n_classes: int) -> np.ndarray:
    """K x K counts, rows true class, columns predicted class, classes 0..K-1 (all of them)."""
    t, p = _pair(y_true, y_pred, n_classes)
    return np.bincount(t * n_classes + p, minlength=n_classes**2).reshape(n_classes, n_classes)


def _rates(cm: np.ndarray) -> dict[str, np.ndarray]:
    """Metrics of a stack of confusion matrices (..., K, K), vectorised."""
    with np.errstate(invalid="ignore", divide="ignore"):
        diag = np.diagonal(cm, axis1=-2, axis2=-1).astype(float)
        rows, cols = cm.sum(-1).astype(float), cm.sum(-2).astype(float)
        n = rows.sum(-1)
        present, seen = rows > 0, (rows + cols) > 0
        recall = np.where(present, diag / rows, NAN)
        f1 = np.where(seen, 2 * diag / (rows + cols), NAN)
        n_present, n_seen = present.sum(-1), seen.sum(-1)
        return {
            "accuracy": np.where(n > 0, diag.sum(-1) / n, NAN),
            "balanced_accuracy": np.where(n_present > 0, np.nansum(recall, -1) / n_present, NAN),
            "macro_f1": np.where(n_seen > 0, np.nansum(f1, -1) / n_seen, NAN),
        }


def accuracy(y_true: Any, y_pred: Any) -> float:
    """Share of predictions equal to the truth; NaN for empty input."""
    t, p = np.asarray(y_true).ravel(), np.asarray(y_pred).ravel()
    return float(np.mean(t == p)) if t.size else NAN


def balanced_accuracy(y_true: Any, y_pred: Any, n_classes: int) -> float:
    """Mean recall over the classes present in the truth (scikit-learn's definition)."""
    return float(_rates(confusion_matrix(y_true, y_pred, n_classes))["balanced_accuracy"])


def macro_f1(y_true: Any, y_pred: Any, n_classes: int) -> float:
    """Mean F1 = 2TP / (2TP + FP + FN) over classes present or predicted (F1 0 when TP = 0)."""
    return float(_rates(confusion_matrix(y_true, y_pred, n_classes))["macro_f1"])


def per_class(cm: np.ndarray) -> dict[str, list[float | None]]:
    """Per class, in label order: support, recall, precision, F1 (NaN where undefined)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        diag = np.diag(cm).astype(float)
        rows, cols = cm.sum(1).astype(float), cm.sum(0).astype(float)
        recall = np.where(rows > 0, diag / rows, NAN)
        precision = np.where(cols > 0, diag / cols, NAN)
        f1 = np.where(rows + cols > 0, 2 * diag / (rows + cols), NAN)
    return {"support": [int(v) for v in rows], "recall": _list(recall),
            "precision": _list(precision), "f1": _list(f1)}


def group_accuracy(y_true: Any, y_pred: Any, groups: Sequence[str]) -> dict[str, dict[str, Any]]:
    """Accuracy per group (e.g. object), groups sorted by name: {group: {n, accuracy}}."""
    t, p, g = np.asarray(y_true).ravel(), np.asarray(y_pred).ravel(), np.asarray(groups)
    out = {}
    for name in sorted(set(g.tolist())):
        m = g == name
        out[str(name)] = {"n": int(m.sum()), "accuracy": accuracy(t[m], p[m])}
    return out


def worst_group(per_group: dict[str, dict[str, Any]]) -> dict[str, Any] | None:
    """The group of lowest accuracy (ties: first name); None when there is no group."""
    if not per_group:
        return None
    name = min(per_group, key=lambda k: (per_group[k]["accuracy"], k))
    return {"group": name, **per_group[name]}


def bin_distance(y_true: Any, y_pred: Any) -> np.ndarray:
    """Bins between direction classes the shortest way round the circle: 0..4."""
    d = (np.asarray(y_pred, dtype=np.int64) - np.asarray(y_true, dtype=np.int64)) % N_DIRECTIONS
    return np.minimum(d, N_DIRECTIONS - d)


def direction_metrics(y_true: Any, y_pred: Any) -> dict[str, Any]:
    """Adjacent share of errors ((pred - true) mod 8 in {1, 7} among wrong predictions),
    within-one-bin accuracy and mean absolute angular error (45 degrees a bin, shortest way)."""
    t, p = _pair(y_true, y_pred, N_DIRECTIONS)
    dist = bin_distance(t, p)
    errors = int((dist > 0).sum())
    return {
        "adjacent_error_share": float((dist == 1).sum() / errors) if errors else NAN,
        "within_one_bin": float(np.mean(dist <= 1)) if t.size else NAN,
        "mean_abs_angular_error_deg": float(np.mean(dist) * BIN_DEG) if t.size else NAN,
        "error_bins": [int(v) for v in np.bincount(dist, minlength=5)],
    }


def cascade(state_true: Any, state_pred: Any, dir_true: Any, dir_pred: Any,
            slip: int = 2) -> dict[str, Any]:
    """Direction scored on the truly slipping sequences, two ways.

    `dir_true`/`dir_pred` hold one entry per sample (ignored unless the true state is slip).
    state given: accuracy of the direction head on the true slips; end to end: a true slip
    counts as correct only if its state is predicted slip and its direction is right (a wrong
    state is a miss).
    """
    st, sp = np.asarray(state_true).ravel(), np.asarray(state_pred).ravel()
    dt, dp = np.asarray(dir_true).ravel(), np.asarray(dir_pred).ravel()
    m = st == slip
    ok = dt[m] == dp[m]
    n = int(m.sum())
    return {"n_slip": n,
            "state_given_accuracy": float(ok.mean()) if n else NAN,
            "end_to_end_accuracy": float((ok & (sp[m] == slip)).mean()) if n else NAN,
            "slips_missed_by_state": float((sp[m] != slip).mean()) if n else NAN}


def bootstrap_indices(n: int, reps: int = BOOTSTRAP, seed: int = 0) -> np.ndarray:
    """reps x n sample positions drawn with replacement (numpy Generator seeded by `seed`)."""
    return np.random.default_rng(seed).integers(0, n, size=(reps, n)) if n else \
        np.zeros((reps, 0), np.int64)


def interval(values: np.ndarray, level: float = 0.95) -> list[float]:
    """Percentile interval of bootstrap values (NaN values dropped; all NaN -> [NaN, NaN])."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if not v.size:
        return [NAN, NAN]
    a = (1 - level) / 2
    return [float(np.quantile(v, a)), float(np.quantile(v, 1 - a))]


def bootstrap_ci(fn: Callable[..., float], *arrays: Any, reps: int = BOOTSTRAP, seed: int = 0,
                 level: float = 0.95) -> list[float]:
    """95 % percentile interval of fn(*arrays) over seeded resamples of the samples.

    Generic (a Python loop); the classification reports use a vectorised equivalent.
    """
    arrs = [np.asarray(a) for a in arrays]
    idx = bootstrap_indices(len(arrs[0]), reps, seed)
    return interval(np.array([fn(*(a[i] for a in arrs)) for i in idx]), level)


def classification_report(y_true: Any, y_pred: Any, n_classes: int,
                          groups: Sequence[str] | None = None, reps: int = BOOTSTRAP,
                          seed: int = 0) -> dict[str, Any]:
    """Accuracy, balanced accuracy, macro-F1 (each with a bootstrap 95 % interval), the
    confusion matrix, per-class figures and per-group (object) and worst-group accuracy."""
    t, p = _pair(y_true, y_pred, n_classes)
    cm = confusion_matrix(t, p, n_classes)
    out: dict[str, Any] = {"n": int(t.size)}
    rates = _rates(cm)
    idx = bootstrap_indices(t.size, reps, seed)
    codes = t * n_classes + p
    k2 = n_classes * n_classes
    flat = (codes[idx] + (np.arange(reps) * k2)[:, None]).ravel()
    boot = _rates(np.bincount(flat, minlength=reps * k2).reshape(reps, n_classes, n_classes))
    for name, value in rates.items():
        out[name] = float(value)
        out[f"{name}_ci95"] = [float(value)] * 2 if t.size == 1 else interval(boot[name])
    out["confusion"] = cm.tolist()
    out["per_class"] = per_class(cm)
    if groups is not None:
        out["per_object"] = group_accuracy(t, p, groups)
        w = worst_group(out["per_object"])
        out["worst_object"] = None if w is None else {"object": w["group"], "n": w["n"],
                                                      "accuracy": w["accuracy"]}
    return out


def seed_summary(values: Sequence[float]) -> dict[str, Any]:
    """Mean and spread of one metric over seeds: n, mean, std (ddof 1; NaN for one seed),
    min, max. NaN values are left out; none left gives NaN everywhere."""
    v = np.asarray([x for x in values if x is not None], dtype=float)
    v = v[np.isfinite(v)]
    if not v.size:
        return {"n": 0, "mean": NAN, "std": NAN, "min": NAN, "max": NAN}
    return {"n": int(v.size), "mean": float(v.mean()),
            "std": float(v.std(ddof=1)) if v.size > 1 else NAN,
            "min": float(v.min()), "max": float(v.max())}


def _list(a: np.ndarray) -> list[float]:
    return [float(x) for x in a]


def jsonable(obj: Any) -> Any:
    """obj with NaN and infinities replaced by None and numpy scalars by Python ones."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if np.isfinite(obj) else None
    return obj
