"""Depth metrics against hand-worked cases."""

import math

import numpy as np
import pytest

from vtsbench.depth.metrics import depth_errors, peak_depth_error, plane_aligned_rmse, rmse


def test_plane_is_removed_exactly() -> None:
    y, x = np.mgrid[0:20, 0:30].astype(float)
    true = np.exp(-((x - 15) ** 2 + (y - 10) ** 2) / 20)
    pred = true + 0.3 + 0.01 * x - 0.02 * y
    assert plane_aligned_rmse(pred, true) < 1e-12
    assert rmse(pred, true) > 0.1


def test_hand_worked_values() -> None:
    true = np.zeros((2, 2))
    pred = np.array([[1.0, -1.0], [-1.0, 1.0]])  # a saddle: no plane fits it
    assert plane_aligned_rmse(pred, true) == pytest.approx(1.0)
    assert rmse(pred, true) == pytest.approx(1.0)
    assert peak_depth_error(pred, true) == pytest.approx(1.0)
    region = np.array([[True, False], [False, False]])
    assert rmse(pred, true, region) == pytest.approx(1.0)
    assert peak_depth_error(np.full((2, 2), 0.5), np.ones((2, 2))) == pytest.approx(-0.5)


def test_edges_empty_tiny_and_bad_shapes() -> None:
    z = np.zeros((3, 3))
    none = np.zeros((3, 3), bool)
    assert math.isnan(plane_aligned_rmse(z, z, none)) and math.isnan(rmse(z, z, none))
    one = none.copy()
    one[1, 1] = True
    assert plane_aligned_rmse(z + 5, z, one) == 0.0
    with pytest.raises(ValueError):
        rmse(np.zeros((3, 3)), np.zeros((3, 4)))
    with pytest.raises(ValueError):
        rmse(z, z, np.ones((2, 2), bool))


def test_depth_errors_bundle() -> None:
    true = np.zeros((5, 5))
    true[2, 2] = 1.0
    pred = true * 0.9
    e = depth_errors(pred, true, true > 0)
    assert e.contact_rmse_mm == pytest.approx(0.1) and e.peak_depth_error_mm == pytest.approx(-0.1)
    assert set(e.to_dict()) == {"plane_aligned_rmse_mm", "contact_rmse_mm", "peak_depth_error_mm"}
