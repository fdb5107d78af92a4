"""Metrics against scikit-learn on random cases, and hand-worked direction and edge cases."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from sklearn import metrics as skm

from vtsbench.evaluation import metrics as M


@pytest.mark.parametrize("seed", range(20))
def test_against_sklearn(seed: int) -> None:
    rng = np.random.default_rng(seed)
    k = int(rng.integers(1, 9))
    n = int(rng.integers(1, 60))
    t = rng.integers(0, k, n)
    p = np.where(rng.random(n) < 0.6, t, rng.integers(0, k, n))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert M.accuracy(t, p) == pytest.approx(skm.accuracy_score(t, p))
        assert M.balanced_accuracy(t, p, k) == pytest.approx(skm.balanced_accuracy_score(t, p))
        assert M.macro_f1(t, p, k) == pytest.approx(
            skm.f1_score(t, p, average="macro", zero_division=0))
    np.testing.assert_array_equal(M.confusion_matrix(t, p, k),
                                  skm.confusion_matrix(t, p, labels=list(range(k))))
    rep = M.classification_report(t, p, k, reps=50)
    assert rep["accuracy"] == pytest.approx(skm.accuracy_score(t, p))
    f1 = skm.f1_score(t, p, labels=list(range(k)), average=None, zero_division=0)
    for c in range(k):
        if rep["per_class"]["support"][c] or c in p:
            assert rep["per_class"]["f1"][c] == pytest.approx(f1[c])


def test_direction_wrap_hand_worked() -> None:
    d = M.direction_metrics([0], [7])
    assert d["within_one_bin"] == 1.0 and d["mean_abs_angular_error_deg"] == 45.0
    assert d["adjacent_error_share"] == 1.0 and d["error_bins"] == [0, 1, 0, 0, 0]
    d = M.direction_metrics([0], [4])
    assert d["mean_abs_angular_error_deg"] == 180.0 and d["within_one_bin"] == 0.0
    assert d["adjacent_error_share"] == 0.0
    d = M.direction_metrics([7, 1, 2, 6], [0, 7, 2, 1])  # adjacent, 2 bins, right, 3 bins
    assert d["error_bins"] == [1, 1, 1, 1, 0]
    assert d["adjacent_error_share"] == pytest.approx(1 / 3)
    assert d["within_one_bin"] == 0.5
    assert d["mean_abs_angular_error_deg"] == pytest.approx((45 + 90 + 135) / 4)
    assert math.isnan(M.direction_metrics([3], [3])["adjacent_error_share"])  # no error


def test_cascade() -> None:
    st = [2, 2, 2, 2, 0, 1]
    sp = [2, 2, 0, 2, 2, 1]
    dt = [0, 3, 5, 6, 0, 0]
    dp = [0, 3, 5, 7, 4, 4]
    c = M.cascade(st, sp, dt, dp)
    assert c["n_slip"] == 4
    assert c["state_given_accuracy"] == 0.75  # the third is right though its state is wrong
    assert c["end_to_end_accuracy"] == 0.5
    assert c["slips_missed_by_state"] == 0.25
    assert math.isnan(M.cascade([0], [0], [0], [0])["end_to_end_accuracy"])


def test_edges() -> None:
    assert math.isnan(M.accuracy([], []))
    rep = M.classification_report([], [], 3)
    assert rep["n"] == 0 and math.isnan(rep["accuracy"]) and rep["confusion"] == [[0] * 3] * 3
    one = M.classification_report([1], [1], 3, groups=["a"])
    assert one["accuracy"] == 1.0 and one["accuracy_ci95"] == [1.0, 1.0]
    assert one["worst_object"] == {"object": "a", "n": 1, "accuracy": 1.0}
    # a single class, always right; a class never predicted; a class never present
    assert M.balanced_accuracy([0, 0], [0, 0], 3) == 1.0
    assert M.macro_f1([0, 0], [0, 0], 3) == 1.0
    pc = M.per_class(M.confusion_matrix([0, 1], [0, 0], 3))
    assert pc["recall"][1] == 0.0 and math.isnan(pc["precision"][1]) and pc["f1"][1] == 0.0
    assert math.isnan(pc["recall"][2]) and math.isnan(pc["f1"][2])
    assert M.macro_f1([0, 1], [0, 0], 3) == pytest.approx((2 / 3 + 0) / 2)
    with pytest.raises(ValueError, match=r"0\.\.2"):
        M.confusion_matrix([0], [3], 3)


def test_bootstrap_seeded_and_consistent() -> None:
    rng = np.random.default_rng(0)
    t = rng.integers(0, 3, 200)
    p = np.where(rng.random(200) < 0.8, t, 0)
    a = M.classification_report(t, p, 3, seed=1)
    b = M.classification_report(t, p, 3, seed=1)
    assert a["accuracy_ci95"] == b["accuracy_ci95"]
    lo, hi = a["accuracy_ci95"]
    assert lo < a["accuracy"] < hi and hi - lo < 0.15
    # the vectorised interval equals the generic one on the same resamples
    assert M.bootstrap_ci(M.accuracy, t, p, seed=1) == pytest.approx(a["accuracy_ci95"])


def test_group_and_seed_summary() -> None:
    g = M.group_accuracy([0, 1, 1, 2], [0, 0, 1, 2], ["b", "a", "a", "c"])
    assert g == {"a": {"n": 2, "accuracy": 0.5}, "b": {"n": 1, "accuracy": 1.0},
                 "c": {"n": 1, "accuracy": 1.0}}
    assert M.worst_group(g)["group"] == "a" and M.worst_group({}) is None
    s = M.seed_summary([0.9, 0.8, None, float("nan")])
    assert s["n"] == 2 and s["mean"] == pytest.approx(0.85)
    assert s["std"] == pytest.approx(np.std([0.9, 0.8], ddof=1))
    assert math.isnan(M.seed_summary([0.5])["std"]) and M.seed_summary([])["n"] == 0
    assert M.jsonable({"a": float("nan"), "b": [np.int64(2)]}) == {"a": None, "b": [2]}
