"""The colour-to-gradient mappings: recovery on held-out presses, batching, odd inputs."""

from __future__ import annotations

import numpy as np
import pytest

from tests.fixtures.calibration import fitted
from vtsbench.depth.mapping import (
    LutMapping,
    PolyMapping,
    exponents,
    fit_mapping,
    mapping_from_arrays,
    norm_xy,
)
from vtsbench.depth.sphere import sphere_fields
from vtsbench.errors import VtsError

#: Held-out gradient RMSE (mm/mm, over the trusted cap) each method must reach on the small
#: simulated set (8 presses to train, 2 held out, within the training depths). Measured per
#: press: lut (24 bins, 2x2 cells) 0.071 and 0.079, poly 0.032 and 0.046, mlp (12 epochs)
#: 0.030 and 0.061.
THRESHOLD = {"lut": 0.15, "poly": 0.12, "mlp": 0.12}
METHODS = ["lut", "poly", "mlp"]


@pytest.mark.parametrize("method", METHODS)
def test_mapping_recovers_gradients_on_held_out_presses(tmp_path_factory, method) -> None:
    run = fitted(tmp_path_factory, method)
    cal = run.calibration
    assert len(run.held_out) == 2
    for r in run.held_out:
        p = r.press
        f = sphere_fields(cal.resolution, p.x, p.y, p.r, p.ball_radius_mm, cal.mm_per_px,
                          cal.rim)
        g = cal.gradients(p.image)
        err = np.hypot(g[..., 0] - f.p, g[..., 1] - f.q)[f.trusted]
        rmse = float(np.sqrt(np.mean(err**2)))
        assert rmse == pytest.approx(r.errors["gradient_rmse"], rel=1e-5)
        assert rmse < THRESHOLD[method], (method, p.id, rmse)
        # Flat gel far from the contact maps to (nearly) zero.
        assert float(np.abs(g[f.flat]).mean()) < 0.03
    assert cal.fit["train_gradient_rmse_cap"] < 0.1


@pytest.mark.parametrize("method", METHODS)
def test_batched_prediction_matches_frames_and_is_float32(tmp_path_factory, method) -> None:
    cal = fitted(tmp_path_factory, method).calibration
    rng = np.random.default_rng(0)
    h, w = cal.resolution
    diff = rng.normal(0, 30, (2, 3, h, w, 3)).astype(np.float32)
    g = cal.mapping.predict(diff)
    assert g.shape == (2, 3, h, w, 2) and g.dtype == np.float32
    np.testing.assert_allclose(g[1, 2], cal.mapping.predict(diff[1, 2]), atol=1e-5)


@pytest.mark.parametrize("method", METHODS)
def test_extreme_colours_give_finite_gradients(tmp_path_factory, method) -> None:
    cal = fitted(tmp_path_factory, method).calibration
    h, w = cal.resolution
    frames = np.stack([np.full((h, w, 3), 255, np.uint8), np.zeros((h, w, 3), np.uint8),
                       np.full((h, w, 3), 77, np.uint8)])
    frames[2, :, : w // 2] = 255
    g = cal.gradients(frames)
    assert np.isfinite(g).all()
    # Inputs are clipped to the calibrated colour range, so the output stays bounded.
    assert np.abs(g).max() < 50


@pytest.mark.parametrize("method", METHODS)
def test_background_maps_to_exactly_zero(tmp_path_factory, method) -> None:
    cal = fitted(tmp_path_factory, method).calibration
    g = cal.gradients(np.stack([cal.background, cal.background]))
    assert (g == 0).all()


@pytest.mark.parametrize("method", METHODS)
def test_torch_prediction_matches_numpy(tmp_path_factory, method) -> None:
    torch = pytest.importorskip("torch")
    cal = fitted(tmp_path_factory, method).calibration
    run = fitted(tmp_path_factory, method)
    img = np.stack([run.held_out[0].press.image, cal.background])
    g_np = cal.gradients(img)
    g_t = cal.gradients_torch(torch.from_numpy(img)).numpy()
    assert g_t.dtype == np.float32 and g_t.shape == g_np.shape
    assert (g_t[1] == 0).all()
    # lut bins may flip where a blurred colour sits on a bin edge: compare in bulk.
    close = np.abs(g_t - g_np) < 1e-3
    assert close.mean() > (0.995 if method == "lut" else 0.9999)


def test_lut_fills_empty_bins_from_the_nearest_filled_one() -> None:
    rng = np.random.default_rng(1)
    colour = rng.uniform(-100, 100, (400, 3)).astype(np.float32)
    colour[:, 1:] = 0  # only the red axis is ever seen
    xy = rng.uniform(-1, 1, (400, 2)).astype(np.float32)
    target = np.column_stack([colour[:, 0] / 100, np.zeros(400)]).astype(np.float32)
    m = LutMapping.fit(colour, xy, target, bins=8, cells=2)
    assert np.isfinite(m.table).all()
    # A colour never seen (green and blue at their extremes) takes a red-axis neighbour's value.
    far = m.predict_flat(np.array([[90.0, 100.0, -100.0]], np.float32),
                         np.zeros((1, 2), np.float32))
    near = m.predict_flat(np.array([[90.0, 0.0, 0.0]], np.float32), np.zeros((1, 2), np.float32))
    np.testing.assert_allclose(far, near)


def test_poly_recovers_a_polynomial_exactly() -> None:
    rng = np.random.default_rng(2)
    colour = rng.uniform(-120, 120, (3000, 3)).astype(np.float32)
    xy = rng.uniform(-1, 1, (3000, 2)).astype(np.float32)
    z = colour / 64
    target = np.column_stack([0.3 * z[:, 0] - 0.1 * z[:, 1] * z[:, 2] * xy[:, 0],
                              0.2 * z[:, 2] ** 2 + 0.05 * xy[:, 1] ** 2]).astype(np.float32)
    m = PolyMapping.fit(colour, xy, target, degree=2, pos_degree=2, ridge=0.0)
    np.testing.assert_allclose(m.predict_flat(colour, xy), target, atol=1e-4)


def test_exponents_and_coordinates() -> None:
    assert exponents(4, 3).shape[0] == 35 and exponents(2, 2).shape[0] == 6
    assert tuple(exponents(2, 2)[0]) == (0, 0)
    x, y = norm_xy(4, 6)
    assert x[0] == pytest.approx(-1 + 1 / 6) and x[-1] == pytest.approx(1 - 1 / 6)
    assert y.shape == (4,) and y.dtype == np.float32


def test_bad_parameters_and_arrays() -> None:
    c = np.zeros((10, 3), np.float32)
    with pytest.raises(VtsError, match="unknown method"):
        fit_mapping("spline", c, c[:, :2], c[:, :2])
    with pytest.raises(VtsError, match="degree"):
        fit_mapping("poly", c, c[:, :2], c[:, :2], degree=0)
    with pytest.raises(VtsError, match="bins"):
        fit_mapping("lut", c, c[:, :2], c[:, :2], bins=1)
    with pytest.raises(ValueError, match="wrong shape"):
        mapping_from_arrays("poly", {"degree": 2, "pos_degree": 1},
                            {"poly.coef": np.zeros((3, 2))})


def test_mlp_is_deterministic(tmp_path_factory) -> None:
    pytest.importorskip("torch")
    rng = np.random.default_rng(3)
    colour = rng.normal(0, 40, (2000, 3)).astype(np.float32)
    xy = rng.uniform(-1, 1, (2000, 2)).astype(np.float32)
    target = (colour[:, :2] / 100).astype(np.float32)
    a = fit_mapping("mlp", colour, xy, target, epochs=3, width=16, depth=2, seed=5, device="cpu")
    b = fit_mapping("mlp", colour, xy, target, epochs=3, width=16, depth=2, seed=5, device="cpu")
    for k in a.arrays:
        np.testing.assert_array_equal(a.arrays[k], b.arrays[k])
    assert a.params["width"] == 16 and a.params["trained_on"] == "cpu"


def test_mlp_with_position_inputs_and_torch_agree() -> None:
    torch = pytest.importorskip("torch")
    rng = np.random.default_rng(4)
    colour = rng.normal(0, 40, (1500, 3)).astype(np.float32)
    xy = rng.uniform(-1, 1, (1500, 2)).astype(np.float32)
    target = (colour[:, :2] / 100 * (1 + 0.2 * xy[:, :1])).astype(np.float32)
    m = fit_mapping("mlp", colour, xy, target, epochs=2, width=8, depth=1, xy_input=True,
                    pos_degree=1, device="cpu")
    back = mapping_from_arrays("mlp", m.params, m.arrays)
    diff = rng.normal(0, 40, (2, 6, 7, 3)).astype(np.float32)
    a = back.predict(diff)
    b = back.predict_torch(torch.from_numpy(diff)).numpy()
    assert a.shape == (2, 6, 7, 2)
    np.testing.assert_allclose(a, b, atol=1e-5)


def test_mlp_without_torch_says_so(monkeypatch) -> None:
    import sys

    monkeypatch.setitem(sys.modules, "torch", None)  # import torch now raises ImportError
    c = np.zeros((10, 3), np.float32)
    with pytest.raises(VtsError, match=r"needs torch .*lut and poly do not"):
        fit_mapping("mlp", c, c[:, :2], c[:, :2])


@pytest.mark.parametrize("degree,pos_degree", [(3, 2), (2, 0), (4, 1)])
def test_poly_row_layout_predict_equals_the_chunked_form(degree, pos_degree) -> None:
    """PolyMapping.predict (monomials as rows, one product per chunk, cached position rows)
    gives the numbers of the per-sample form predict_flat, over several frames and sizes."""
    from vtsbench.depth.mapping import Mapping, PolyMapping, exponents

    rng = np.random.default_rng(degree)
    t = exponents(degree, 3).shape[0] * exponents(pos_degree, 2).shape[0]
    m = PolyMapping({"degree": degree, "pos_degree": pos_degree, "ridge": 1e-6, "terms": t},
                    {"poly.coef": rng.normal(0, 0.1, (t, 2)).astype(np.float32)})
    for shape in ((2, 300, 250, 3), (37, 41, 3)):
        d = rng.normal(0, 20, shape).astype(np.float32)
        np.testing.assert_allclose(m.predict(d), Mapping.predict(m, d), rtol=1e-5, atol=1e-6)
