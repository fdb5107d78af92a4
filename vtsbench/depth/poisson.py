"""Poisson integration of surface gradients (p, q) = (dz/dx, dz/dy) into depth z (mm).

Grid: z[i, j] at pixel centres, x along the columns (spacing hx mm), y down the rows (hy mm).
The solvers share one discretisation, so that the divergence and the Laplacian match:

    forward-difference gradient   (Dx z)[i, j] = (z[i, j+1] - z[i, j]) / hx
                                  (Dy z)[i, j] = (z[i+1, j] - z[i, j]) / hy
    backward-difference divergence  D^T g
    5-point Laplacian               D^T D z = D^T (p, q)     (the least-squares normal equations)

Each solver differs only in what lies beyond the frame (or beyond the contact mask):

    "dst"     z = 0 on a ghost ring around the frame (Dirichlet); DST-I diagonalises D^T D.
    "dct"     no edge crosses the frame border (Neumann); DCT-II diagonalises D^T D.
    "masked"  z = 0 on every pixel outside the mask and on the ghost ring; sparse direct solve.

Sampling of the input gradients:

    "forward"  p[i, j] = (z[i, j+1] - z[i, j]) / hx, q[i, j] = (z[i+1, j] - z[i, j]) / hy
               exactly (the solver's own discretisation; reconstructs to rounding).
    "point"    p, q are derivatives sampled at the pixel centres (a calibrated mapping's
               output); the edge value between two centres is their mean (trapezoid rule,
               second order); the last column of p (last row of q) keeps its own sample.

See docs/poisson.md for the formulas, boundary conditions and measured speed.
"""

from __future__ import annotations

import functools
import math
import os

import numpy as np
import scipy.fft

from vtsbench.errors import VtsError

SOLVERS = ("dst", "dct", "masked")
SAMPLINGS = ("point", "forward")


# --------------------------------------------------------------------------- input handling


def spacing(mm_per_px: float | tuple[float, float]) -> tuple[float, float]:
    """(hx, hy) in mm from a scalar or an (x, y) pair; ValueError unless positive and finite."""
    if np.ndim(mm_per_px) == 0:
        hx = hy = float(mm_per_px)  # type: ignore[arg-type]
    else:
        vals = [float(v) for v in np.asarray(mm_per_px, dtype=np.float64).ravel()]
        if len(vals) != 2:
            raise ValueError(f"mm_per_px must be a number or an (x, y) pair, got {mm_per_px!r}")
        hx, hy = vals
    if not (math.isfinite(hx) and math.isfinite(hy) and hx > 0 and hy > 0):
        raise ValueError(f"mm_per_px must be positive and finite, got {mm_per_px!r}")
    return hx, hy


def result_dtype(p_dtype: np.dtype, q_dtype: np.dtype, dtype: object = None) -> np.dtype:
    """float64 when asked for or when either input is float64 (or wider), else float32."""
    if dtype is not None:
        dt = np.dtype(dtype)
        if dt not in (np.float32, np.float64):
            raise ValueError(f"dtype must be float32 or float64, got {dt}")
        return dt
    for d in (p_dtype, q_dtype):
        if np.issubdtype(d, np.complexfloating):
            raise ValueError(f"gradients must be real, got {d}")
        if np.issubdtype(d, np.floating) and np.dtype(d).itemsize >= 8:
            return np.dtype(np.float64)
    return np.dtype(np.float32)


def _check_inputs(p: object, q: object, dtype: object) -> tuple[np.ndarray, np.ndarray]:
    p_arr, q_arr = np.asarray(p), np.asarray(q)
    if p_arr.shape != q_arr.shape:
        raise ValueError(f"p and q shapes differ: {p_arr.shape} vs {q_arr.shape}")
    if p_arr.ndim < 2:
        raise ValueError(f"expected gradients of shape (..., H, W), got {p_arr.shape}")
    dt = result_dtype(p_arr.dtype, q_arr.dtype, dtype)
    p_arr, q_arr = p_arr.astype(dt, copy=False), q_arr.astype(dt, copy=False)
    if not (np.isfinite(p_arr).all() and np.isfinite(q_arr).all()):
        bad = int((~np.isfinite(p_arr)).sum() + (~np.isfinite(q_arr)).sum())
        raise VtsError(f"gradients contain NaN or inf ({bad} values); mask or fill them first")
    return p_arr, q_arr


def staggered(p: np.ndarray, q: np.ndarray, sampling: str) -> tuple[np.ndarray, np.ndarray]:
    """Forward-edge slopes from the input sampling ("forward": as given; "point": trapezoid)."""
    if sampling == "forward":
        return p, q
    if sampling != "point":
        raise ValueError(f"sampling must be one of {SAMPLINGS}, got {sampling!r}")
    gx = p.copy()
    gx[..., :-1] += p[..., 1:]
    gx[..., :-1] *= 0.5
    gy = q.copy()
    gy[..., :-1, :] += q[..., 1:, :]
    gy[..., :-1, :] *= 0.5
    return gx, gy


def divergence(gx: np.ndarray, gy: np.ndarray, hx: float, hy: float,
               boundary: str) -> np.ndarray:
    """D^T g: backward-difference divergence of forward-edge slopes (the solvers' right side).

    boundary "dirichlet": gx[..., j] is the edge from column j to j + 1, the last one to the
    ghost column; the missing edge from the ghost column to column 0 has zero slope (same in y).
    boundary "neumann": no edge crosses the border; the last column of gx (row of gy) is unused.
    Units: slope / mm, so that (D^T D) z = D^T g with D^T D = Lx / hx^2 + Ly / hy^2.
    """
    ax, ay = gx / hx, gy / hy
    if boundary == "neumann":
        ax[..., -1] = 0.0
        ay[..., -1, :] = 0.0
    b = -ax
    b -= ay
    b[..., 1:] += ax[..., :-1]
    b[..., 1:, :] += ay[..., :-1, :]
    return b


# --------------------------------------------------------------------------- spectral solvers


def laplacian_eigenvalues(n: int, h: float, kind: str) -> np.ndarray:
    """Eigenvalues of the 1-D second difference D^T D / h^2 of length n, float64.

    dst (Dirichlet, ghost zeros at -1 and n):  4 sin^2(pi (k + 1) / (2 (n + 1))) / h^2
    dct (Neumann, no edges off the ends):       4 sin^2(pi k / (2 n)) / h^2, k = 0 .. n - 1
    (written with sin^2 rather than 2 - 2 cos to keep the small ones accurate).
    """
    k = np.arange(n, dtype=np.float64)
    if kind == "dst":
        return 4.0 * np.sin(np.pi * (k + 1.0) / (2.0 * (n + 1))) ** 2 / h**2
    return 4.0 * np.sin(np.pi * k / (2.0 * n)) ** 2 / h**2


@functools.lru_cache(maxsize=32)
def inverse_eigenvalues(kind: str, height: int, width: int, dtype: str, hx: float,
                        hy: float) -> np.ndarray:
    """1 / (lambda_y[k] + lambda_x[l]) on the (H, W) spectral grid, 0 where lambda is 0 (cached).

    Only the dct grid has a zero eigenvalue, at (0, 0): the free constant, set to 0 there.
    """
    lam = (laplacian_eigenvalues(height, hy, kind)[:, None]
           + laplacian_eigenvalues(width, hx, kind)[None, :])
    inv = np.zeros_like(lam)
    np.divide(1.0, lam, out=inv, where=lam > 0)
    inv = inv.astype(dtype)
    inv.setflags(write=False)
    return inv


@functools.lru_cache(maxsize=32)
def border_mask(height: int, width: int) -> np.ndarray:
    """The frame's outermost ring of pixels (all pixels of a frame one or two pixels wide)."""
    m = np.zeros((height, width), bool)
    m[0, :] = m[-1, :] = True
    m[:, 0] = m[:, -1] = True
    m.setflags(write=False)
    return m


def transform_threads() -> int:
    """Threads a batch's transforms are split over: the CPUs this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # no sched_getaffinity (macOS, Windows)
        return max(1, os.cpu_count() or 1)


def _spectral_solve(b: np.ndarray, inv: np.ndarray, kind: str) -> np.ndarray:
    """T^-1(T(b) * inv) over the last two axes (T: orthonormal DST-I or DCT-II), each frame on
    one thread and a batch split over short-lived threads.

    Not scipy.fft's own threads (`workers` > 1): they start pocketfft's pool, whose fork
    handler can lose the wake-up of a worker it then waits for, so a later fork hangs, as a
    torch DataLoader's workers starting one after another do (four forks in a row, in a loop
    for 30 s beside another such run on 2 cores: 2 of 6 runs hung after a DCT with
    workers=-1, none of 6 with workers=1). The threads here end with the call: nothing is
    left to fork. The two transforms of one 480x640 frame take 1.9-2.1 ms against 1.2-1.4 ms
    with scipy's threads, but the whole `integrate` is no slower (2 cores, alternated: 3.9-4.0
    against 4.0-4.6 ms a frame, 32-33 against 34-35 ms for a batch of 8)."""
    fwd, back, typ = ((scipy.fft.dstn, scipy.fft.idstn, 1) if kind == "dst"
                      else (scipy.fft.dctn, scipy.fft.idctn, 2))

    def solve(x: np.ndarray) -> np.ndarray:
        t = fwd(x, type=typ, axes=(-2, -1), norm="ortho", workers=1)
        t *= inv
        return back(t, type=typ, axes=(-2, -1), norm="ortho", workers=1)

    frames = b.reshape(-1, *b.shape[-2:])
    k = min(len(frames), transform_threads())
    if k <= 1:
        return solve(b)
    from concurrent.futures import ThreadPoolExecutor

    parts = np.array_split(np.arange(len(frames)), k)
    with ThreadPoolExecutor(k) as pool:
        done = list(pool.map(lambda i: solve(frames[i[0]:i[-1] + 1]), parts))
    return np.concatenate(done).reshape(b.shape)


def _solve_dst(b: np.ndarray, hx: float, hy: float) -> np.ndarray:
    inv = inverse_eigenvalues("dst", *b.shape[-2:], b.dtype.str, hx, hy)
    return _spectral_solve(b, inv, "dst")


def _solve_dct(b: np.ndarray, hx: float, hy: float) -> np.ndarray:
    inv = inverse_eigenvalues("dct", *b.shape[-2:], b.dtype.str, hx, hy)
    # inv[0, 0] = 0: the mean of z is 0 here, fixed below
    z = _spectral_solve(b, inv, "dct")
    # The constant is free under Neumann conditions: put the border pixels' median at 0 depth
    # (an untouched gel edge). The median ignores a contact that reaches part of the border.
    z -= np.median(z[..., border_mask(*z.shape[-2:])], axis=-1)[..., None, None]
    return z


# --------------------------------------------------------------------------- masked solver
#
# The masked system is the 5-point Dirichlet Laplacian restricted to the mask pixels. Measured
# on 480x640 frames, float64, one frame, 2-core AMD EPYC (single runs, machine shared):
#
#   mask (share of frame)       splu COLAMD   splu MMD(A'+A)   splu nested dissection   PCG-DST
#   disc 10 %                       0.30 s          0.13 s             0.10 s             0.36 s
#   disc 40 %                       1.51 s          0.68 s             0.50 s             0.75 s
#   irregular blob 10 %             0.24 s          0.12 s             0.09 s             0.57 s
#   irregular blob 40 %             1.07 s          0.61 s             0.49 s             0.89 s
#
# PCG-DST is conjugate gradients preconditioned by the DST solve on the mask's bounding box
# (37-67 iterations to 1e-12 relative residual). The direct solve with a geometric
# nested-dissection ordering (below) is the fastest in every case and has no tolerance, so it is
# used; it always runs in float64 (single-precision LU of a Laplacian loses ~cond * 6e-8).

_ND_LEAF = 64  # leaf block size of the nested dissection (32-64 measured best)


def nested_dissection(ys: np.ndarray, xs: np.ndarray, leaf: int = _ND_LEAF) -> np.ndarray:
    """An elimination order of grid pixels: split at the median row or column, separator last."""
    order: list[np.ndarray] = []
    stack: list[tuple[np.ndarray, bool]] = [(np.arange(ys.size), False)]
    # Explicit stack: entries flagged True are separators/leaves ready to append in order.
    while stack:
        idx, done = stack.pop()
        if done or idx.size <= leaf:
            order.append(idx)
            continue
        y, x = ys[idx], xs[idx]
        c = y if np.ptp(y) >= np.ptp(x) else x
        mid = int(np.median(c))
        lo, hi, sep = idx[c < mid], idx[c > mid], idx[c == mid]
        if lo.size == 0 or hi.size == 0:
            order.append(idx)
            continue
        # Pushed in reverse: lo is eliminated first, then hi, then the separator.
        stack.extend([(sep, True), (hi, False), (lo, False)])
    return np.concatenate(order) if order else np.zeros(0, np.intp)


def _solve_masked_frame(b: np.ndarray, mask: np.ndarray, hx: float, hy: float) -> np.ndarray:
    """z with (D^T D z)[m] = b[m] on mask pixels m and z = 0 elsewhere (float64)."""
    z = np.zeros(b.shape, np.float64)
    ys, xs = np.nonzero(mask)
    n = ys.size
    if n == 0:
        return z
    perm = nested_dissection(ys, xs)
    ys, xs = ys[perm], xs[perm]
    index = np.full(mask.shape, -1, np.int64)
    index[ys, xs] = np.arange(n)
    rows, cols, vals = [np.arange(n)], [np.arange(n)], [np.full(n, 2 / hx**2 + 2 / hy**2)]
    for a, c, w in ((index[:, :-1], index[:, 1:], -1 / hx**2),
                    (index[:-1, :], index[1:, :], -1 / hy**2)):
        both = (a >= 0) & (c >= 0)
        i0, i1 = a[both], c[both]
        rows += [i0, i1]
        cols += [i1, i0]
        vals += [np.full(i0.size, w), np.full(i0.size, w)]
    import scipy.sparse  # here: about 50 ms to import, and only the masked solver needs it
    import scipy.sparse.linalg

    mat = scipy.sparse.csc_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
    lu = scipy.sparse.linalg.splu(mat, permc_spec="NATURAL", diag_pivot_thresh=0.0,
                                  options={"SymmetricMode": True})
    z[ys, xs] = lu.solve(b[ys, xs].astype(np.float64))
    return z


def _broadcast_mask(mask: object, shape: tuple[int, ...]) -> np.ndarray:
    m = np.asarray(mask)
    if m.dtype != bool:
        raise ValueError(f"mask must be boolean, got {m.dtype}")
    if m.ndim < 2 or m.shape[-2:] != shape[-2:]:
        raise ValueError(f"mask shape {m.shape} does not match gradients {shape}")
    try:
        full = np.broadcast_shapes(m.shape, shape)
    except ValueError:
        full = None
    if full != shape:
        raise ValueError(f"mask shape {m.shape} does not match gradients {shape}")
    return np.broadcast_to(m, shape)


# --------------------------------------------------------------------------- public entry


def integrate(p: np.ndarray, q: np.ndarray, *, method: str = "dct",
              mask: np.ndarray | None = None, mm_per_px: float | tuple[float, float] = 1.0,
              sampling: str = "point", dtype: object = None) -> np.ndarray:
    """Depth (mm, positive into the gel) from slopes p = dz/dx, q = dz/dy of shape (..., H, W).

    method: "dst" (z = 0 beyond the frame), "dct" (zero flux at the border; the border pixels'
    median is set to 0) or "masked" (z = 0 off the mask; mask (..., H, W) bool, or estimated
    from the gradients by vtsbench.depth.mask.mask_from_gradients when None).
    mm_per_px: pixel size, a number or (x, y). sampling: "point" (derivatives at pixel centres)
    or "forward" (forward differences, the solver's own discretisation: exact).
    dtype: float32 for float32 or integer input, float64 for float64 input, unless given.
    Leading dimensions are a batch; the result has the shape of p.
    """
    if method not in SOLVERS:
        raise ValueError(f"method must be one of {SOLVERS}, got {method!r}")
    if sampling not in SAMPLINGS:
        raise ValueError(f"sampling must be one of {SAMPLINGS}, got {sampling!r}")
    if mask is not None and method != "masked":
        raise ValueError(f"a mask is only used by method='masked', not {method!r}")
    hx, hy = spacing(mm_per_px)
    p_arr, q_arr = _check_inputs(p, q, dtype)
    shape, dt = p_arr.shape, p_arr.dtype
    if mask is not None:
        mask = _broadcast_mask(mask, shape)
    if 0 in shape:
        return np.zeros(shape, dt)

    gx, gy = staggered(p_arr, q_arr, sampling)
    if method == "dct":
        return _solve_dct(divergence(gx, gy, hx, hy, "neumann"), hx, hy).astype(dt, copy=False)
    b = divergence(gx, gy, hx, hy, "dirichlet")
    if method == "dst":
        return _solve_dst(b, hx, hy).astype(dt, copy=False)

    if mask is None:
        from vtsbench.depth.mask import mask_from_gradients

        mask = mask_from_gradients(p_arr, q_arr)
    height, width = shape[-2:]
    frames_b = b.reshape(-1, height, width)
    frames_m = np.broadcast_to(mask, shape).reshape(-1, height, width)
    out = np.empty(frames_b.shape, dt)
    for k in range(frames_b.shape[0]):
        out[k] = _solve_masked_frame(frames_b[k], frames_m[k], hx, hy)
    return out.reshape(shape)
