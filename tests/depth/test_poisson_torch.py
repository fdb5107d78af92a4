"""The torch Poisson solvers against the numpy ones (on the CPU)."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from vtsbench.depth.mask import mask_from_gradients  # noqa: E402
from vtsbench.depth.poisson import SOLVERS, divergence, integrate, staggered  # noqa: E402
from vtsbench.depth.poisson_torch import (  # noqa: E402
    _dct2,
    _dst1,
    _idct2,
    integrate_torch,
    masked_pcg,
)
from vtsbench.errors import VtsError  # noqa: E402

ANISO = (0.03, 0.045)


def sphere_slopes(height=64, width=80, mm=0.03, depth=0.1):
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    x, y = (x - width / 2) * mm, (y - height / 2 + 0.4) * mm
    r2 = x * x + y * y
    inside = r2 < 6 * depth - depth * depth
    s = np.sqrt(np.maximum(9 - r2, 1e-12))
    return np.where(inside, -x / s, 0.0), np.where(inside, -y / s, 0.0)


def relerr(a, b) -> float:
    a = a.numpy() if isinstance(a, torch.Tensor) else a
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


def test_transforms_match_scipy() -> None:
    import scipy.fft

    x = np.random.default_rng(0).standard_normal((3, 7, 9))
    t = torch.from_numpy(x)
    for n_axis, dim in ((9, -1), (7, -2)):
        assert relerr(_dst1(t, dim), scipy.fft.dst(x, type=1, axis=dim) / 2) < 1e-13
        assert relerr(_dct2(t, dim), scipy.fft.dct(x, type=2, axis=dim)) < 1e-13
        assert relerr(_idct2(_dct2(t, dim), dim), x) < 1e-13
        assert n_axis == x.shape[dim]


@pytest.mark.parametrize("method", SOLVERS)
@pytest.mark.parametrize("sampling", ["point", "forward"])
def test_matches_numpy_float64_and_float32(method: str, sampling: str) -> None:
    rng = np.random.default_rng(1)
    sp, sq = sphere_slopes()
    cases = [(sp, sq, 0.03), (sp + 0.01 * rng.standard_normal(sp.shape), sq, ANISO),
             (rng.standard_normal((2, 3, 33, 47)), rng.standard_normal((2, 3, 33, 47)), ANISO)]
    for p, q, mm in cases:
        mask = mask_from_gradients(p, q) if p.ndim == 2 else rng.random(p.shape) < 0.7
        kw = {"mask": mask} if method == "masked" else {}
        kwt = {"mask": torch.from_numpy(mask)} if method == "masked" else {}
        ref = integrate(p, q, method=method, mm_per_px=mm, sampling=sampling, **kw)
        got = integrate_torch(torch.from_numpy(p), torch.from_numpy(q), method=method,
                              mm_per_px=mm, sampling=sampling, **kwt)
        assert got.dtype == torch.float64 and got.shape == p.shape
        assert relerr(got, ref) < 1e-9
        got32 = integrate_torch(torch.from_numpy(p).float(), torch.from_numpy(q).float(),
                                method=method, mm_per_px=mm, sampling=sampling, **kwt)
        assert got32.dtype == torch.float32
        assert relerr(got32.double(), ref) < 1e-4


@pytest.mark.parametrize("shape", [(1, 1), (2, 2), (3, 5), (7, 1), (1, 7)])
@pytest.mark.parametrize("method", SOLVERS)
def test_tiny_sizes_match_numpy(shape, method: str) -> None:
    rng = np.random.default_rng(2)
    p, q = rng.standard_normal(shape), rng.standard_normal(shape)
    kw = {"mask": np.ones(shape, bool)} if method == "masked" else {}
    kwt = {"mask": torch.ones(shape, dtype=torch.bool)} if method == "masked" else {}
    ref = integrate(p, q, method=method, **kw)
    got = integrate_torch(torch.from_numpy(p), torch.from_numpy(q), method=method, **kwt)
    assert torch.isfinite(got).all() and relerr(got, ref) < 1e-12


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_masked_pcg_matches_direct_solve(dtype) -> None:
    """The CG path used on GPUs, run here on the CPU against the sparse direct solve."""
    rng = np.random.default_rng(3)
    p, q = sphere_slopes()
    p = np.stack([p, p + 0.02 * rng.standard_normal(p.shape), np.zeros_like(p)])
    q = np.stack([q, q + 0.02 * rng.standard_normal(q.shape), np.zeros_like(q)])
    masks = mask_from_gradients(p, q)
    masks[1, 5:9, 5:70] = True  # a second, thin region
    assert not masks[2].any()
    ref = integrate(p, q, method="masked", mask=masks, mm_per_px=ANISO)
    b = divergence(*staggered(p, q, "point"), *ANISO, "dirichlet")
    got = masked_pcg(torch.from_numpy(b).to(dtype), torch.from_numpy(masks), *ANISO)
    assert got.dtype == dtype
    assert relerr(got.double(), ref) < (1e-9 if dtype == torch.float64 else 1e-4)
    assert (got[2] == 0).all()
    full = masked_pcg(torch.from_numpy(b), torch.ones(64, 80, dtype=torch.bool), *ANISO)
    assert relerr(full, integrate(p, q, method="dst", mm_per_px=ANISO)) < 1e-10
    assert (masked_pcg(torch.from_numpy(b), torch.zeros(64, 80, dtype=torch.bool), 1, 1) == 0).all()


def test_zero_field_errors_and_inputs() -> None:
    zero = torch.zeros(2, 9, 11)
    for method in SOLVERS:
        assert (integrate_torch(zero, zero, method=method) == 0).all()
    assert integrate_torch(np.zeros((4, 5), np.int16), np.ones((4, 5), np.int16),
                           method="dst").dtype == torch.float32
    bad = torch.zeros(5, 6, dtype=torch.float64)
    bad[1, 2] = float("nan")
    with pytest.raises(VtsError, match="gradients contain NaN or inf"):
        integrate_torch(bad, torch.zeros_like(bad))
    with pytest.raises(ValueError, match="shapes differ"):
        integrate_torch(torch.zeros(5, 6), torch.zeros(5, 7))
    with pytest.raises(ValueError, match="mask shape"):
        integrate_torch(torch.zeros(5, 6), torch.zeros(5, 6), method="masked",
                        mask=torch.ones(5, 7, dtype=torch.bool))
    with pytest.raises(ValueError, match="method"):
        integrate_torch(torch.zeros(5, 6), torch.zeros(5, 6), method="fft")
    assert integrate_torch(torch.zeros(0, 4), torch.zeros(0, 4)).shape == (0, 4)


def test_estimated_mask_matches_numpy() -> None:
    p, q = sphere_slopes()
    ref = integrate(p, q, method="masked", mm_per_px=0.03)
    got = integrate_torch(torch.from_numpy(p), torch.from_numpy(q), method="masked",
                          mm_per_px=0.03)
    assert relerr(got, ref) < 1e-12


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
@pytest.mark.parametrize("method", SOLVERS)
def test_cuda_matches_numpy(method: str) -> None:
    p, q = sphere_slopes()
    mask = mask_from_gradients(p, q)
    kw = {"mask": mask} if method == "masked" else {}
    kwt = {"mask": torch.from_numpy(mask).cuda()} if method == "masked" else {}
    ref = integrate(p, q, method=method, mm_per_px=0.03, **kw)
    got = integrate_torch(torch.from_numpy(p).cuda(), torch.from_numpy(q).cuda(),
                          method=method, mm_per_px=0.03, **kwt)
    assert got.device.type == "cuda" and relerr(got.cpu(), ref) < 1e-9
