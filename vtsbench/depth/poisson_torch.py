"""Poisson integration on torch tensors (any device): the solvers of vtsbench.depth.poisson.

Same discretisation, boundary conditions, sampling and results as the numpy path (see that
module and docs/poisson.md). torch has no DST/DCT, so both are done with real FFTs of an
extended sequence, along the last two dimensions, batched over the leading ones:

    DST-I of x (length N):  y = [0, x, 0, -reversed x] (length 2N + 2), Y = rfft(y),
                            S[k] = -Im Y[k + 1] / 2 = sum_n x[n] sin(pi (k + 1)(n + 1) / (N + 1));
                            the inverse is the same transform times 2 / (N + 1).
    DCT-II of x:            y = [x, reversed x] (length 2N), Y = rfft(y),
                            C[k] = Re(exp(-i pi k / 2N) Y[k])
                                 = 2 sum_n x[n] cos(pi k (2n + 1) / 2N);
                            the inverse puts exp(+i pi k / 2N) C[k] (and 0 at k = N) back
                            through irfft of length 2N and keeps the first N values.

"masked" on a CUDA (or other non-CPU) device runs a batched conjugate-gradient solve
preconditioned by the DST solver on the masks' common bounding box (masked_pcg below). On the
CPU it hands each frame to the numpy sparse direct solver instead, which measured faster there
(docs/poisson.md has the figures). This module imports torch; vtsbench does not import it.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import torch

from vtsbench.depth.poisson import (
    SAMPLINGS,
    SOLVERS,
    border_mask,
    inverse_eigenvalues,
    spacing,
)
from vtsbench.depth.poisson import integrate as integrate_numpy
from vtsbench.errors import VtsError

# --------------------------------------------------------------------------- transforms


def _dst1(x: torch.Tensor, dim: int) -> torch.Tensor:
    """Unnormalised DST-I along dim: S[k] = sum_n x[n] sin(pi (k+1)(n+1) / (N+1))."""
    x = x.movedim(dim, -1)
    n = x.shape[-1]
    zero = x.new_zeros((*x.shape[:-1], 1))
    y = torch.cat([zero, x, zero, -x.flip(-1)], dim=-1)
    s = torch.fft.rfft(y, dim=-1).imag[..., 1:n + 1] * -0.5
    return s.movedim(-1, dim)


def _twiddle(n: int, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    k = torch.arange(n, dtype=dtype, device=device)
    return torch.polar(torch.ones_like(k), -math.pi * k / (2 * n))


def _dct2(x: torch.Tensor, dim: int) -> torch.Tensor:
    """Unnormalised DCT-II along dim: C[k] = 2 sum_n x[n] cos(pi k (2n+1) / 2N)."""
    x = x.movedim(dim, -1)
    n = x.shape[-1]
    y = torch.fft.rfft(torch.cat([x, x.flip(-1)], dim=-1), dim=-1)[..., :n]
    c = (y * _twiddle(n, x.dtype, x.device)).real
    return c.movedim(-1, dim)


def _idct2(c: torch.Tensor, dim: int) -> torch.Tensor:
    """Inverse of _dct2 along dim."""
    c = c.movedim(dim, -1)
    n = c.shape[-1]
    spec = c * _twiddle(n, c.dtype, c.device).conj()
    spec = torch.cat([spec, spec.new_zeros((*spec.shape[:-1], 1))], dim=-1)
    x = torch.fft.irfft(spec, n=2 * n, dim=-1)[..., :n]
    return x.movedim(-1, dim)


@functools.lru_cache(maxsize=32)
def _inverse_eigenvalues_on(kind: str, height: int, width: int, dtype: torch.dtype,
                            device: str, hx: float, hy: float) -> torch.Tensor:
    np_dtype = "<f8" if dtype == torch.float64 else "<f4"
    inv = inverse_eigenvalues(kind, height, width, np_dtype, hx, hy)
    return torch.as_tensor(np.array(inv), dtype=dtype, device=device)


@functools.lru_cache(maxsize=32)
def _border_on(height: int, width: int, device: str) -> torch.Tensor:
    return torch.as_tensor(np.array(border_mask(height, width)), device=device)


def _solve_dst(b: torch.Tensor, hx: float, hy: float) -> torch.Tensor:
    h, w = b.shape[-2:]
    inv = _inverse_eigenvalues_on("dst", h, w, b.dtype, str(b.device), hx, hy)
    s = _dst1(_dst1(b, -1), -2) * inv
    return _dst1(_dst1(s, -1), -2) * (4.0 / ((h + 1) * (w + 1)))


def _solve_dct(b: torch.Tensor, hx: float, hy: float) -> torch.Tensor:
    h, w = b.shape[-2:]
    inv = _inverse_eigenvalues_on("dct", h, w, b.dtype, str(b.device), hx, hy)
    z = _idct2(_idct2(_dct2(_dct2(b, -1), -2) * inv, -1), -2)
    border = z[..., _border_on(h, w, str(z.device))].sort(dim=-1).values
    n = border.shape[-1]
    median = 0.5 * (border[..., (n - 1) // 2] + border[..., n // 2])  # as numpy.median
    return z - median[..., None, None]


# --------------------------------------------------------------------------- shared steps


def _staggered(p: torch.Tensor, q: torch.Tensor,
               sampling: str) -> tuple[torch.Tensor, torch.Tensor]:
    if sampling == "forward":
        return p, q
    gx, gy = p.clone(), q.clone()
    gx[..., :-1] = 0.5 * (p[..., :-1] + p[..., 1:])
    gy[..., :-1, :] = 0.5 * (q[..., :-1, :] + q[..., 1:, :])
    return gx, gy


def _divergence(gx: torch.Tensor, gy: torch.Tensor, hx: float, hy: float,
                boundary: str) -> torch.Tensor:
    ax, ay = gx / hx, gy / hy
    if boundary == "neumann":
        ax[..., -1] = 0.0
        ay[..., -1, :] = 0.0
    b = -ax - ay
    b[..., 1:] += ax[..., :-1]
    b[..., 1:, :] += ay[..., :-1, :]
    return b


def _laplacian(z: torch.Tensor, hx: float, hy: float) -> torch.Tensor:
    """D^T D z with z = 0 beyond the array (the 5-point Dirichlet Laplacian, positive)."""
    ix, iy = 1.0 / hx**2, 1.0 / hy**2
    out = z * (2 * ix + 2 * iy)
    out[..., 1:] -= ix * z[..., :-1]
    out[..., :-1] -= ix * z[..., 1:]
    out[..., 1:, :] -= iy * z[..., :-1, :]
    out[..., :-1, :] -= iy * z[..., 1:, :]
    return out


def masked_pcg(b: torch.Tensor, mask: torch.Tensor, hx: float, hy: float, *,
               tol: float | None = None, max_iter: int = 1000) -> torch.Tensor:
    """Solve (D^T D z)[m] = b[m] on mask pixels, z = 0 elsewhere, by batched PCG.

    b, mask (..., H, W). Works on the masks' common bounding box; the preconditioner is the
    DST (Dirichlet) solve on that box restricted to the mask, which is exact for a mask that
    fills the box. Stops when every frame's residual is below tol times its right side
    (default 1e-12 in float64, 1e-6 in float32) or after max_iter iterations.
    """
    if tol is None:
        tol = 1e-12 if b.dtype == torch.float64 else 1e-6
    shape = b.shape
    z = torch.zeros_like(b)
    m = mask.to(torch.bool).expand(shape)
    if not bool(m.any()):
        return z
    rows = torch.nonzero(m.reshape(-1, *shape[-2:]).any(dim=(0, 2))).flatten()
    cols = torch.nonzero(m.reshape(-1, *shape[-2:]).any(dim=(0, 1))).flatten()
    r0, r1, c0, c1 = int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1
    mb = m[..., r0:r1, c0:c1].to(b.dtype)
    r = b[..., r0:r1, c0:c1] * mb
    x = torch.zeros_like(r)

    def dot(u: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
        return (u * v).sum(dim=(-2, -1))

    def precondition(v: torch.Tensor) -> torch.Tensor:
        return _solve_dst(v, hx, hy) * mb

    limit = tol * torch.sqrt(dot(r, r))
    s = precondition(r)
    d = s.clone()
    rs = dot(r, s)
    for _ in range(max_iter):
        active = torch.sqrt(dot(r, r)) > limit
        if not bool(active.any()):
            break
        ad = _laplacian(d, hx, hy) * mb
        dad = dot(d, ad)
        alpha = torch.where(active & (dad > 0), rs / torch.where(dad > 0, dad, 1), 0)
        x += alpha[..., None, None] * d
        r -= alpha[..., None, None] * ad
        s = precondition(r)
        rs_new = dot(r, s)
        beta = torch.where(active & (rs > 0), rs_new / torch.where(rs > 0, rs, 1), 0)
        d = s + beta[..., None, None] * d
        rs = rs_new
    z[..., r0:r1, c0:c1] = x * mb
    return z


# --------------------------------------------------------------------------- public entry


def _as_tensor(a: object) -> torch.Tensor:
    return a if isinstance(a, torch.Tensor) else torch.as_tensor(np.asarray(a))


def integrate_torch(p: torch.Tensor, q: torch.Tensor, *, method: str = "dct",
                    mask: torch.Tensor | None = None,
                    mm_per_px: float | tuple[float, float] = 1.0,
                    sampling: str = "point") -> torch.Tensor:
    """Depth (mm) from slopes p = dz/dx, q = dz/dy (..., H, W) on p's device.

    As vtsbench.depth.poisson.integrate: method "dst", "dct" or "masked"; float64 for float64
    input, float32 otherwise; result shaped like p. A missing mask for "masked" is estimated
    on the CPU by mask_from_gradients.
    """
    if method not in SOLVERS:
        raise ValueError(f"method must be one of {SOLVERS}, got {method!r}")
    if sampling not in SAMPLINGS:
        raise ValueError(f"sampling must be one of {SAMPLINGS}, got {sampling!r}")
    if mask is not None and method != "masked":
        raise ValueError(f"a mask is only used by method='masked', not {method!r}")
    hx, hy = spacing(mm_per_px)
    p, q = _as_tensor(p), _as_tensor(q)
    if p.shape != q.shape:
        raise ValueError(f"p and q shapes differ: {tuple(p.shape)} vs {tuple(q.shape)}")
    if p.ndim < 2:
        raise ValueError(f"expected gradients of shape (..., H, W), got {tuple(p.shape)}")
    if p.is_complex() or q.is_complex():
        raise ValueError("gradients must be real")
    dt = torch.float64 if torch.float64 in (p.dtype, q.dtype) else torch.float32
    p, q = p.to(dt), q.to(device=p.device, dtype=dt)
    if not bool(torch.isfinite(p).all() & torch.isfinite(q).all()):
        bad = int((~torch.isfinite(p)).sum() + (~torch.isfinite(q)).sum())
        raise VtsError(f"gradients contain NaN or inf ({bad} values); mask or fill them first")
    if mask is not None:
        mask = _as_tensor(mask).to(p.device)
        if mask.dtype != torch.bool:
            raise ValueError(f"mask must be boolean, got {mask.dtype}")
        try:
            full = torch.broadcast_shapes(mask.shape, p.shape)
        except RuntimeError:
            full = None
        if mask.ndim < 2 or full != p.shape:
            raise ValueError(f"mask shape {tuple(mask.shape)} does not match gradients "
                             f"{tuple(p.shape)}")
    if p.numel() == 0:
        return torch.zeros_like(p)

    if method == "masked" and (p.device.type == "cpu" or mask is None):
        np_mask = None if mask is None else mask.cpu().numpy()
        if p.device.type == "cpu":
            z = integrate_numpy(p.detach().numpy(), q.detach().numpy(), method="masked",
                                mask=np_mask, mm_per_px=(hx, hy), sampling=sampling)
            return torch.from_numpy(z)
        if np_mask is None:
            from vtsbench.depth.mask import mask_from_gradients

            np_mask = mask_from_gradients(p.detach().cpu().numpy(),
                                          q.detach().cpu().numpy())
        mask = torch.from_numpy(np_mask).to(p.device)

    gx, gy = _staggered(p, q, sampling)
    if method == "dct":
        return _solve_dct(_divergence(gx, gy, hx, hy, "neumann"), hx, hy)
    b = _divergence(gx, gy, hx, hy, "dirichlet")
    if method == "dst":
        return _solve_dst(b, hx, hy)
    return masked_pcg(b, mask, hx, hy)
