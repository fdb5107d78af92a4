"""Poisson integration: exactness on analytic shapes, the mismatch bug, sampling, stability."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from vtsbench.depth.mask import clean_mask, disc, mask_from_gradients, mask_from_images
from vtsbench.depth.poisson import (
    SOLVERS,
    _solve_dct,
    divergence,
    integrate,
    inverse_eigenvalues,
    nested_dissection,
)
from vtsbench.errors import VtsError

H, W = 64, 80
MM = 0.03
ANISO = (0.03, 0.045)


# --------------------------------------------------------------------------- shapes


def grid(height: int, width: int, mm: float | tuple[float, float], cy: float, cx: float):
    hx, hy = (mm, mm) if np.ndim(mm) == 0 else mm
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    return (x - cx) * hx, (y - cy) * hy


def sphere_cap(height=H, width=W, mm=MM, radius=3.0, depth=0.1, cy=31.3, cx=40.6):
    """A 3 mm sphere pressed `depth` mm into the gel: depth, slopes, contact, radial distance."""
    x, y = grid(height, width, mm, cy, cx)
    r2 = x * x + y * y
    a2 = 2 * radius * depth - depth * depth
    inside = r2 < a2
    s = np.sqrt(np.maximum(radius * radius - r2, 1e-12))
    z = np.where(inside, s - (radius - depth), 0.0)
    return z, np.where(inside, -x / s, 0.0), np.where(inside, -y / s, 0.0), inside, np.sqrt(r2), \
        np.sqrt(a2)


def cone(height=H, width=W, mm=MM, depth=0.2, slope=0.4):
    x, y = grid(height, width, mm, height / 2 - 0.2, width / 2 + 0.3)
    return np.maximum(depth - slope * np.hypot(x, y), 0.0)


def sine_texture(height=H, width=W, amp=0.01):
    """A texture that is 0 on the outermost rows and columns."""
    i, j = np.mgrid[0:height, 0:width].astype(np.float64)
    u, v = np.pi * i / (height - 1), np.pi * j / (width - 1)
    return amp * (np.sin(3 * u) * np.sin(5 * v) + 0.5 * np.sin(u) * np.sin(2 * v)
                  + 0.2 * np.sin(7 * u) * np.sin(4 * v))


def forward(z: np.ndarray, mm=MM, last=0.0):
    """Forward differences with z = 0 beyond the last column/row (the dst/masked sampling)."""
    hx, hy = (mm, mm) if np.ndim(mm) == 0 else mm
    zp = np.pad(z, [(0, 0)] * (z.ndim - 2) + [(0, 1), (0, 1)], constant_values=last)
    return ((zp[..., :-1, 1:] - zp[..., :-1, :-1]) / hx,
            (zp[..., 1:, :-1] - zp[..., :-1, :-1]) / hy)


# --------------------------------------------------------------------------- exactness


@pytest.mark.parametrize("mm", [MM, ANISO])
@pytest.mark.parametrize("method", SOLVERS)
def test_sphere_cap_and_cone_are_exact(method: str, mm) -> None:
    for z in (sphere_cap(mm=mm)[0], cone(mm=mm)):
        p, q = forward(z, mm)
        kw = {"mask": z > 0} if method == "masked" else {}
        got = integrate(p, q, method=method, mm_per_px=mm, sampling="forward", **kw)
        assert got.dtype == np.float64
        assert np.abs(got - z).max() < 1e-6
        assert np.abs(got - z).max() < 1e-12  # in fact to rounding


@pytest.mark.parametrize("mm", [MM, ANISO])
def test_sine_texture_exact_under_dst(mm) -> None:
    z = sine_texture()
    p, q = forward(z, mm)
    assert np.abs(integrate(p, q, method="dst", mm_per_px=mm, sampling="forward") - z).max() \
        < 1e-12


@pytest.mark.parametrize("mm", [MM, ANISO])
def test_ramp_and_any_shape_exact_under_dct_up_to_constant(mm) -> None:
    x, y = grid(H, W, mm, 0, 0)
    rng = np.random.default_rng(3)
    for z in (0.3 + 0.05 * x - 0.02 * y, sine_texture() + 0.1 * x * y + 0.2,
              rng.standard_normal((H, W))):
        p, q = forward(z, mm)
        p[:, -1] = rng.standard_normal(H)  # the last column of p and row of q are unused
        q[-1, :] = rng.standard_normal(W)
        got = integrate(p, q, method="dct", mm_per_px=mm, sampling="forward")
        diff = got - z
        assert np.ptp(diff) < 1e-10
        ring = np.r_[got[0], got[-1], got[1:-1, 0], got[1:-1, -1]]
        assert abs(np.median(ring)) < 1e-12  # the constant: border median at zero depth


def test_sphere_cap_batched_and_anisotropic_all_solvers() -> None:
    z = np.stack([sphere_cap(mm=ANISO, depth=d)[0] for d in (0.05, 0.1, 0.15)])
    p, q = forward(z, ANISO)
    for method in SOLVERS:
        kw = {"mask": z > 0} if method == "masked" else {}
        got = integrate(p, q, method=method, mm_per_px=ANISO, sampling="forward", **kw)
        assert got.shape == z.shape
        assert np.abs(got - z).max() < 1e-12


def test_mismatched_central_difference_divergence_is_not_exact() -> None:
    """The gs_sdk-type bug: a central-difference divergence with the 5-point Laplacian."""
    z = sphere_cap()[0]
    p, q = forward(z)
    matched = _solve_dct(divergence(p, q, MM, MM, "neumann"), MM, MM)
    assert np.abs(matched - z).max() < 1e-12
    # Central differences of the same field (what np.gradient gives), paired with the same
    # Laplacian: D^T D z is not what the central divergence of central slopes produces.
    pc, qc = np.gradient(z, MM, axis=1), np.gradient(z, MM, axis=0)
    central = -(np.gradient(pc, MM, axis=1) + np.gradient(qc, MM, axis=0))
    wrong = _solve_dct(central, MM, MM)
    err = np.abs(wrong - z).max()
    assert err > 1e-3 * z.max()  # off by far more than rounding
    assert err > 1e6 * np.abs(matched - z).max()


# --------------------------------------------------------------------------- point sampling


@pytest.mark.parametrize("method", SOLVERS)
def test_point_sampling_sphere_cap_error_is_small(method: str) -> None:
    # 64x80 at 0.03 mm/px, 3 mm sphere 0.1 mm deep (contact radius 26 px), analytic slopes at
    # pixel centres. Measured: peak error 0.02-0.15 % of the depth; worst error 3 px or more
    # inside the rim 0.5-1.0 % (the slope jumps at the rim and the trapezoid rule smooths the
    # jump); worst anywhere 1.9 %. Bounds: peak 0.5 %, away from the rim 1.5 %.
    z, p, q, _, r, a = sphere_cap()
    kw = {"mask": mask_from_gradients(p, q)} if method == "masked" else {}
    got = integrate(p, q, method=method, mm_per_px=MM, **kw)
    depth = z.max()
    assert abs(got.max() - depth) < 5e-3 * depth
    away = r < a - 3 * MM
    assert np.abs(got - z)[away].max() < 1.5e-2 * depth
    assert np.abs(got - z).max() < 3e-2 * depth


def test_masked_estimated_mask_reconstructs_sphere_cap_and_dilation_helps() -> None:
    z, p, q, inside, r, a = sphere_cap()
    est = mask_from_gradients(p, q)
    assert est[inside].all()  # reaches over the whole contact ...
    assert not est[r > a + 4 * MM].any()  # ... and only a little beyond it
    assert est[(r > a) & (r < a + 2 * MM)].all()
    got = integrate(p, q, method="masked", mm_per_px=MM)  # mask estimated inside
    assert np.array_equal(got, integrate(p, q, method="masked", mm_per_px=MM, mask=est))
    depth = z.max()
    peak_err = abs(got.max() - depth)
    tight = integrate(p, q, method="masked", mm_per_px=MM,
                      mask=mask_from_gradients(p, q, dilate_px=0))
    # Measured: 0.02 % of the depth with the 2 px dilation, 0.28 % without.
    assert peak_err < 1e-3 * depth
    assert abs(tight.max() - depth) > 3 * peak_err


# --------------------------------------------------------------------------- stability


@pytest.mark.parametrize("method", SOLVERS)
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_zero_field_gives_exactly_zero(method: str, dtype) -> None:
    p = np.zeros((2, 33, 47), dtype)
    kw = {"mask": np.ones(p.shape, bool)} if method == "masked" else {}
    for sampling in ("point", "forward"):
        got = integrate(p, p, method=method, sampling=sampling, **kw)
        assert got.dtype == dtype and got.shape == p.shape
        assert np.all(got == 0)
    if method == "masked":  # estimated mask: nothing to estimate, nothing to solve
        assert np.all(integrate(p, p, method=method) == 0)


@pytest.mark.parametrize("shape", [(1, 1), (2, 2), (3, 5), (7, 1), (1, 7), (2, 1), (33, 47)])
@pytest.mark.parametrize("method", SOLVERS)
def test_tiny_and_odd_sizes(shape, method: str) -> None:
    rng = np.random.default_rng(sum(shape))
    p, q = rng.standard_normal(shape), rng.standard_normal(shape)
    for mm in (1.0, ANISO):
        kw = {"mask": np.ones(shape, bool)} if method == "masked" else {}
        for sampling in ("point", "forward"):
            got = integrate(p, q, method=method, mm_per_px=mm, sampling=sampling, **kw)
            assert got.shape == shape and np.isfinite(got).all()
    # A shape that satisfies the solver's boundary condition comes back exactly. For dst and
    # masked: zero on the first row and column (the missing edge from the ghost ring).
    z = rng.standard_normal(shape)
    if method != "dct":
        z[0, :] = 0
        z[:, 0] = 0
    p, q = forward(z, ANISO)
    kw = {"mask": np.ones(shape, bool)} if method == "masked" else {}
    got = integrate(p, q, method=method, mm_per_px=ANISO, sampling="forward", **kw)
    if method == "dct":
        got, z = got - got.mean(), z - z.mean()
    assert np.abs(got - z).max() < 1e-12


def test_empty_frames() -> None:
    for shape in ((0, 5), (3, 0), (2, 0, 4)):
        for method in SOLVERS:
            assert integrate(np.zeros(shape), np.zeros(shape), method=method).shape == shape


@pytest.mark.parametrize("method", SOLVERS)
def test_float32_matches_float64(method: str) -> None:
    _, p, q, _, _, _ = sphere_cap()
    rng = np.random.default_rng(5)
    noisy_p = p + 0.01 * rng.standard_normal(p.shape)
    noisy_q = q + 0.01 * rng.standard_normal(q.shape)
    mask = mask_from_gradients(p, q)
    kw = {"mask": mask} if method == "masked" else {}
    for pp, qq in ((p, q), (noisy_p, noisy_q)):
        d64 = integrate(pp, qq, method=method, mm_per_px=MM, **kw)
        d32 = integrate(pp.astype(np.float32), qq.astype(np.float32), method=method,
                        mm_per_px=MM, **kw)
        assert d32.dtype == np.float32
        assert np.abs(d32 - d64).max() < 1e-5 * np.abs(d64).max()
        explicit = integrate(pp.astype(np.float32), qq.astype(np.float32), method=method,
                             mm_per_px=MM, dtype=np.float64, **kw)
        assert explicit.dtype == np.float64


def test_dtypes_and_inputs_untouched() -> None:
    z = cone(33, 47)
    p, q = forward(z)
    ints = integrate(np.zeros((4, 5), np.int16), np.ones((4, 5), np.uint8), method="dst")
    assert ints.dtype == np.float32
    assert integrate(p.astype(np.float32), q, method="dct").dtype == np.float64
    for method in SOLVERS:
        pc, qc = p.copy(), q.copy()
        integrate(p, q, method=method, sampling="point")
        integrate(p, q, method=method, sampling="forward")
        assert np.array_equal(p, pc) and np.array_equal(q, qc)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_gradients_raise_one_line_error(bad: float) -> None:
    p = np.zeros((5, 6))
    p[2, 3] = bad
    for method in SOLVERS:
        with pytest.raises(VtsError, match="gradients contain NaN or inf") as info:
            integrate(p, np.zeros_like(p), method=method)
        assert "\n" not in str(info.value)
        with pytest.raises(VtsError):
            integrate(np.zeros_like(p), p.astype(np.float32), method=method)


def test_argument_errors() -> None:
    p = np.zeros((5, 6))
    with pytest.raises(ValueError, match="shapes differ"):
        integrate(p, np.zeros((5, 7)))
    with pytest.raises(ValueError):
        integrate(np.zeros(5), np.zeros(5))
    with pytest.raises(ValueError, match="mask shape"):
        integrate(p, p, method="masked", mask=np.ones((5, 7), bool))
    with pytest.raises(ValueError, match="mask shape"):
        integrate(p, p, method="masked", mask=np.ones((2, 5, 6), bool))
    with pytest.raises(ValueError, match="boolean"):
        integrate(p, p, method="masked", mask=np.ones((5, 6)))
    with pytest.raises(ValueError, match="only used"):
        integrate(p, p, method="dct", mask=np.ones((5, 6), bool))
    with pytest.raises(ValueError, match="method"):
        integrate(p, p, method="fft")
    with pytest.raises(ValueError, match="sampling"):
        integrate(p, p, sampling="central")
    for mm in (0.0, -1.0, np.nan, (1.0, 2.0, 3.0), (1.0, 0.0)):
        with pytest.raises(ValueError, match="mm_per_px"):
            integrate(p, p, mm_per_px=mm)
    with pytest.raises(ValueError, match="dtype"):
        integrate(p, p, dtype=np.float16)


@pytest.mark.parametrize("method", SOLVERS)
def test_batched_equals_per_frame(method: str) -> None:
    rng = np.random.default_rng(7)
    shape = (2, 3, 33, 47)
    p, q = rng.standard_normal(shape), rng.standard_normal(shape)
    mask = rng.random(shape) < 0.7
    kw = {"mask": mask} if method == "masked" else {}
    batch = integrate(p, q, method=method, mm_per_px=ANISO, **kw)
    assert batch.shape == shape
    for i in range(2):
        for j in range(3):
            kw1 = {"mask": mask[i, j]} if method == "masked" else {}
            one = integrate(p[i, j], q[i, j], method=method, mm_per_px=ANISO, **kw1)
            assert np.allclose(batch[i, j], one, rtol=0, atol=1e-12 * np.abs(one).max())


def test_masked_special_masks() -> None:
    rng = np.random.default_rng(11)
    p, q = rng.standard_normal((2, 33, 47)), rng.standard_normal((2, 33, 47))
    empty = integrate(p, q, method="masked", mask=np.zeros((33, 47), bool))
    assert empty.shape == p.shape and np.all(empty == 0)
    full = integrate(p, q, method="masked", mask=np.ones((33, 47), bool), mm_per_px=ANISO)
    dst = integrate(p, q, method="dst", mm_per_px=ANISO)
    assert np.abs(full - dst).max() < 1e-10 * np.abs(dst).max()
    # Off the mask the depth is exactly zero; a one-pixel mask works too.
    mask = np.zeros((33, 47), bool)
    mask[10:20, 5:30] = True
    mask[30, 40] = True
    got = integrate(p, q, method="masked", mask=mask)
    assert np.all(got[:, ~mask] == 0) and np.all(got[:, mask] != 0)


def test_nested_dissection_is_a_permutation() -> None:
    ys, xs = np.nonzero(np.random.default_rng(2).random((90, 70)) < 0.6)
    order = nested_dissection(ys, xs, leaf=16)
    assert np.array_equal(np.sort(order), np.arange(ys.size))
    assert nested_dissection(np.zeros(0, int), np.zeros(0, int)).size == 0


def test_eigenvalue_grids_are_cached() -> None:
    a = inverse_eigenvalues("dst", 33, 47, "<f8", 0.03, 0.03)
    b = inverse_eigenvalues("dst", 33, 47, "<f8", 0.03, 0.03)
    assert a is b and not a.flags.writeable
    assert inverse_eigenvalues("dct", 33, 47, "<f4", 0.03, 0.03)[0, 0] == 0


def test_importing_vtsbench_does_not_import_torch() -> None:
    code = ("import sys, vtsbench.depth.poisson, vtsbench.depth.mask; "
            "sys.exit('torch' in sys.modules)")
    assert subprocess.run([sys.executable, "-c", code], check=False).returncode == 0


# --------------------------------------------------------------------------- masks


def test_mask_from_gradients_fills_drops_and_batches() -> None:
    _, p, q, inside, _, _ = sphere_cap()
    p = p.copy()
    p[5, 5] = p[5, 6] = 1.0  # a two-pixel speck of noise
    m = mask_from_gradients(p, q)
    assert m[inside].all() and not m[:12, :12].any()
    batch = mask_from_gradients(np.stack([p, np.zeros_like(p)]), np.stack([q, np.zeros_like(q)]))
    assert batch.shape == (2, H, W)
    assert np.array_equal(batch[0], m) and not batch[1].any()
    with pytest.raises(ValueError):
        mask_from_gradients(p, q[:, :-1])


def test_clean_mask_closing_holes_and_border() -> None:
    raw = np.zeros((40, 50), bool)
    raw[10:30, 10:30] = True
    raw[15:25, 15:25] = False  # a hole
    raw[10:30, 20] = False  # a one-pixel crack
    raw[0:6, 44:50] = True  # a blob in the corner, touching the border
    m = clean_mask(raw, close_px=2, min_area_px=20, dilate_px=0)
    assert m[10:30, 10:30].all()
    assert m[0:6, 44:50].all()  # not eroded by the border
    assert m.sum() == 400 + 36
    assert disc(0).shape == (1, 1) and disc(2).sum() == 21


def test_mask_from_images() -> None:
    rng = np.random.default_rng(4)
    background = rng.integers(60, 200, (H, W, 3)).astype(np.uint8)
    y, x = np.mgrid[0:H, 0:W]
    blob = np.hypot(x - 40, y - 30) < 12
    frame = background.astype(int)
    frame[blob] += np.array([40, -30, 25])
    frame = np.clip(frame + rng.normal(0, 1.5, frame.shape), 0, 255).astype(np.uint8)
    m = mask_from_images(frame, background)
    assert m[blob].all()
    assert m.sum() < blob.sum() * 1.6
    batch = mask_from_images(np.stack([frame, background]), background)
    assert batch.shape == (2, H, W) and np.array_equal(batch[0], m) and not batch[1].any()
    grey = mask_from_images(frame.mean(-1) / 255, background.mean(-1) / 255, threshold=0.02)
    assert grey[blob].mean() > 0.95
    with pytest.raises(ValueError):
        mask_from_images(frame, background[:, :-1])
