"""Colour-to-gradient mappings f(dR, dG, dB, x, y) -> (p, q) and their features.

Features: the colour difference to the no-contact background in DN (float32, three channels),
and the pixel position normalised to [-1, 1] across the frame (x = -1 at the left edge, +1 at
the right; y likewise down the rows), which lets one mapping follow an illumination that varies
over the gel. Three mappings, all predicting over (..., H, W, 3) differences in batches:

    lut   per coarse spatial cell, a table of the mean gradient for each quantised colour
          difference; empty bins take the value of the nearest filled bin (a bin of the same
          cell first). One lookup per pixel: the fast one.
    poly  least-squares polynomial of the five features up to a total degree (ridge-damped).
    mlp   a small multilayer perceptron (SiLU) trained with Adam in torch; prediction runs in
          numpy too, so a calibration file needs torch only to be made.

Each mapping is described by JSON-able parameters and a dict of float32 arrays, which is what the
calibration file stores; `mapping_from_arrays` rebuilds it.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import VtsError

METHODS = ("lut", "poly", "mlp")
#: Colour differences are divided by this (DN) before poly and mlp see them.
COLOUR_SCALE = 64.0
#: Pixels per chunk when predicting (bounds the temporary memory of poly and mlp).
CHUNK = 1 << 16


def norm_xy(h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    """Normalised pixel-centre coordinates: x (w,) and y (h,) in (-1, 1), float32."""
    x = ((np.arange(w, dtype=np.float64) + 0.5) / w * 2 - 1).astype(np.float32)
    y = ((np.arange(h, dtype=np.float64) + 0.5) / h * 2 - 1).astype(np.float32)
    return x, y


def _flatten(diff: np.ndarray) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:
    """(N, 3) colours and (N, 2) coordinates of (..., H, W, 3) differences, and the lead shape."""
    if diff.ndim < 3 or diff.shape[-1] != 3:
        raise ValueError(f"expected colour differences of shape (..., H, W, 3), got {diff.shape}")
    h, w = diff.shape[-3:-1]
    lead = diff.shape[:-1]
    x, y = norm_xy(h, w)
    xy = np.empty((h, w, 2), np.float32)
    xy[..., 0] = x[None, :]
    xy[..., 1] = y[:, None]
    n_frames = int(np.prod(diff.shape[:-3], dtype=np.int64))
    xy = np.broadcast_to(xy[None], (n_frames, h, w, 2)).reshape(-1, 2)
    return diff.reshape(-1, 3).astype(np.float32, copy=False), xy, lead


class Mapping:
    """Base: subclasses set `method`, implement `predict_flat`, `fit`, and the array round trip."""

    method = ""

    def __init__(self, params: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
        self.params = dict(params)
        self.arrays = {k: np.ascontiguousarray(v, np.float32) for k, v in arrays.items()}

    def predict_flat(self, colour: np.ndarray, xy: np.ndarray) -> np.ndarray:
        """(N, 2) gradients of (N, 3) colour differences (DN) at (N, 2) normalised positions."""
        raise NotImplementedError

    def predict(self, diff: np.ndarray) -> np.ndarray:
        """(..., H, W, 2) float32 gradients of (..., H, W, 3) colour differences in DN."""
        colour, xy, lead = _flatten(np.asarray(diff))
        out = np.empty((colour.shape[0], 2), np.float32)
        for s in range(0, colour.shape[0], CHUNK):
            out[s:s + CHUNK] = self.predict_flat(colour[s:s + CHUNK], xy[s:s + CHUNK])
        return out.reshape(*lead, 2)

    def predict_torch(self, diff: Any) -> Any:
        """The same on a torch tensor (..., H, W, 3) float32, on the tensor's device."""
        raise NotImplementedError

    def relative(self, diff: np.ndarray, zero_map: np.ndarray) -> np.ndarray:
        """f(diff, x, y) - f(0, x, y): (..., H, W, 2) float32 for (..., H, W, 3) differences,
        with zero_map = f(0, x, y); exactly 0 where the difference is exactly 0."""
        g = self.predict(diff)
        g -= zero_map
        # Three elementwise compares: 3x faster than diff.any(axis=-1), a reduction over 3.
        still = (diff[..., 0] == 0) & (diff[..., 1] == 0) & (diff[..., 2] == 0)
        if still.any():
            g[still] = 0.0
        return g


# -- lut --------------------------------------------------------------------------------------


class LutMapping(Mapping):
    """Mean gradient per (spatial cell, quantised colour difference)."""

    method = "lut"

    @property
    def table(self) -> np.ndarray:  # (cells_y, cells_x, bins, bins, bins, 2)
        return self.arrays["lut.table"]

    def _index(self, colour: Any, xy: Any, xp: Any) -> Any:
        """Flat table index of each sample (numpy or torch via xp)."""
        cy, cx, b = self.table.shape[0], self.table.shape[1], self.table.shape[2]
        lo, hi = float(self.params["lo"]), float(self.params["hi"])
        k = (colour - lo) * (b / (hi - lo))
        k = xp.clip(xp.floor(k), 0, b - 1)
        jx = xp.clip(xp.floor((xy[:, 0] + 1) * (cx / 2)), 0, cx - 1)
        jy = xp.clip(xp.floor((xy[:, 1] + 1) * (cy / 2)), 0, cy - 1)
        return (((jy * cx + jx) * b + k[:, 0]) * b + k[:, 1]) * b + k[:, 2]

    def predict_flat(self, colour: np.ndarray, xy: np.ndarray) -> np.ndarray:
        idx = self._index(colour, xy, np).astype(np.int64)
        return self.table.reshape(-1, 2)[idx]

    def relative(self, diff: np.ndarray, zero_map: np.ndarray) -> np.ndarray:
        """f(diff) - f(0) by one lookup in a table from which each cell's f(0) is already taken
        (the same float32 subtraction, so the same numbers as predict - zero_map): the colour
        bins in int32, the cell as a cached per-pixel offset, one np.take of 8-byte entries."""
        diff = np.asarray(diff, np.float32)
        h, w = diff.shape[-3:-1]
        rel = self._relative_table(zero_map)
        if rel is None:  # a zero map that is not this table's own: the general path
            return super().relative(diff, zero_map)
        b = self.table.shape[2]
        lo, hi = float(self.params["lo"]), float(self.params["hi"])
        k = np.subtract(diff, np.float32(lo))
        k *= np.float32(b / (hi - lo))
        np.clip(k, 0, b - 1, out=k)
        ki = k.astype(np.int32)  # floor: non-negative after the clip
        idx = ki[..., 0] * np.int32(b * b)
        idx += ki[..., 1] * np.int32(b)
        idx += ki[..., 2]
        idx += self._cell_offsets(h, w)
        return np.take(rel, idx).view(np.float32).reshape(*diff.shape[:-1], 2)

    def _cell_offsets(self, h: int, w: int) -> np.ndarray:
        """(H, W) int32: the table offset of each pixel's spatial cell (cached per size)."""
        cache = self.__dict__.setdefault("_offsets", {})
        if (h, w) not in cache:
            cy, cx, b = self.table.shape[0], self.table.shape[1], self.table.shape[2]
            x, y = norm_xy(h, w)
            jx = np.clip(np.floor((x + 1) * (cx / 2)), 0, cx - 1).astype(np.int64)
            jy = np.clip(np.floor((y + 1) * (cy / 2)), 0, cy - 1).astype(np.int64)
            cache[(h, w)] = ((jy[:, None] * cx + jx[None, :]) * b**3).astype(np.int32)
        return cache[(h, w)]

    def _relative_table(self, zero_map: np.ndarray) -> np.ndarray | None:
        """The table minus each cell's f(0), as 8-byte entries (int64 view of the (p, q) float32
        pairs), when zero_map is f(0) of this table; else None. Cached per zero map."""
        cached = self.__dict__.get("_rel")
        if cached is not None and cached[0] is zero_map:
            return cached[1]
        h, w = zero_map.shape[:2]
        cy, cx, b = self.table.shape[0], self.table.shape[1], self.table.shape[2]
        flat = self.table.reshape(cy * cx, b**3, 2)
        k0 = int(self._index(np.zeros((1, 3), np.float32), np.zeros((1, 2), np.float32),
                             np)[0]) % b**3  # the bin of a zero difference
        own = flat[:, k0][self._cell_offsets(h, w) // b**3]
        rel = None
        if zero_map.shape == (h, w, 2) and np.array_equal(own, zero_map):
            rel = np.ascontiguousarray(flat - flat[:, k0:k0 + 1]).reshape(-1, 2).view(np.int64)
            rel = rel.reshape(-1)
        self.__dict__["_rel"] = (zero_map, rel)
        return rel

    def predict_torch(self, diff: Any) -> Any:
        import torch

        h, w = diff.shape[-3:-1]
        table = _cached_tensor(self, "lut.table", diff.device).reshape(-1, 2)
        colour = diff.reshape(-1, 3)
        xy = _torch_xy(h, w, diff.device).expand(*diff.shape[:-3], h, w, 2).reshape(-1, 2)
        idx = self._index(colour, xy, torch).long()
        return table[idx].reshape(*diff.shape[:-1], 2)

    @classmethod
    def fit(cls, colour: np.ndarray, xy: np.ndarray, target: np.ndarray, *, bins: int = 32,
            cells: int = 2, **_: Any) -> LutMapping:
        from scipy import ndimage

        if not (2 <= bins <= 256 and 1 <= cells <= 64 and bins**3 * cells**2 <= 1 << 26):
            raise VtsError(f"lut needs 2 <= --bins <= 256 and 1 <= --cells <= 64 with a table of "
                           f"at most 2**26 entries (bins^3 x cells^2), got {bins} and {cells}")
        # One symmetric range for the three channels, wide enough for nearly every sample.
        lim = float(np.percentile(np.abs(colour), 99.9)) * 1.05 + 1.0
        params = {"bins": int(bins), "cells": [int(cells), int(cells)], "lo": -lim, "hi": lim}
        shape = (cells, cells, bins, bins, bins)
        probe = cls(params, {"lut.table": np.zeros((*shape, 2), np.float32)})
        idx = probe._index(colour.astype(np.float64), xy.astype(np.float64), np).astype(np.int64)
        size = int(np.prod(shape))
        count = np.bincount(idx, minlength=size).astype(np.float64)
        table = np.zeros((size, 2), np.float64)
        for c in range(2):
            table[:, c] = np.bincount(idx, weights=target[:, c], minlength=size)
        filled = count > 0
        table[filled] /= count[filled, None]
        if not filled.any():
            raise VtsError("lut: no training samples")
        # Nearest filled bin: a step to the next cell costs as much as the whole colour range,
        # so a bin takes its value from its own cell whenever that cell has any sample.
        _, ind = ndimage.distance_transform_edt(
            ~filled.reshape(shape), sampling=(bins, bins, 1, 1, 1), return_indices=True)
        src = np.ravel_multi_index(tuple(ind), shape)
        table = table[src.ravel()].reshape(*shape, 2)
        return cls(params, {"lut.table": table.astype(np.float32)})


# -- poly -------------------------------------------------------------------------------------


def exponents(degree: int, n_vars: int) -> np.ndarray:
    """All monomial exponents (T, n_vars) of total degree <= degree, graded order."""
    out: list[tuple[int, ...]] = []

    def rec(prefix: tuple[int, ...], left: int) -> None:
        if len(prefix) == n_vars:
            out.append(prefix)
            return
        for e in range(left + 1):
            rec((*prefix, e), left - e)

    rec((), degree)
    out.sort(key=lambda e: (sum(e), [-v for v in e]))
    return np.array(out, np.int64)


def _monomials(cols: list[Any], exps: np.ndarray, xp: Any) -> Any:
    """The (N, T) matrix of monomials of the columns, reusing lower powers."""
    deg = int(exps.max()) if exps.size else 0
    powers = [[xp.ones_like(c)] for c in cols]
    for v, c in enumerate(cols):
        for _ in range(deg):
            powers[v].append(powers[v][-1] * c)
    terms = []
    for e in exps:
        t = powers[0][e[0]]
        for v in range(1, len(cols)):
            if e[v]:
                t = t * powers[v][e[v]]
        terms.append(t)
    return xp.stack(terms, 1)


def pos_basis(xy: Any, degree: int, xp: Any) -> Any:
    """(N, B) monomials of the normalised position of total degree <= degree (1, x, y, ...)."""
    return _monomials([xy[:, 0], xy[:, 1]], exponents(degree, 2), xp)


def _poly_design(colour: Any, xy: Any, degree: int, pos_degree: int, xp: Any) -> Any:
    """(N, Tc * Tp): every colour monomial times every position monomial."""
    z = colour / COLOUR_SCALE
    a = _monomials([z[:, 0], z[:, 1], z[:, 2]], exponents(degree, 3), xp)
    b = pos_basis(xy, pos_degree, xp)
    return (a[:, :, None] * b[:, None, :]).reshape(a.shape[0], -1)


class PolyMapping(Mapping):
    """(p, q) = sum c_ij * colour monomial_i(dR/64, dG/64, dB/64) * position monomial_j(x, y).

    The colour degree sets how finely the colour-to-slope relation bends; the position degree
    (default 2) keeps the spatial variation smooth, so that gel no press reached in training
    gets an interpolated, not an extrapolated, mapping.
    """

    method = "poly"

    def _design(self, colour: Any, xy: Any, xp: Any) -> Any:
        return _poly_design(colour, xy, int(self.params["degree"]),
                            int(self.params["pos_degree"]), xp)

    def predict(self, diff: np.ndarray) -> np.ndarray:
        """(..., H, W, 2) float32 gradients of (..., H, W, 3) differences, frame by frame in
        row layout: the colour monomials as rows (Tc, n) of a reused buffer, one (2 Tp, Tc)
        @ (Tc, n) product, then the position monomials (cached per frame size, (Tp, H W))
        weighted in place. Same sums as predict_flat in another float32 order (differences
        of a few 1e-7 relative); about 3x faster at 480x640."""
        diff = np.asarray(diff)
        if diff.ndim < 3 or diff.shape[-1] != 3:
            return super().predict(diff)
        h, w = diff.shape[-3:-1]
        hw = h * w
        frames = diff.reshape(-1, hw, 3)
        deg = int(self.params["degree"])
        exps = exponents(deg, 3)
        basis = self._basis_rows(h, w)  # (Tp, H W)
        coef_t = self._coef_rows()  # (2 Tp, Tc), row 2 j + k
        out = np.empty((frames.shape[0], hw, 2), np.float32)
        step = CHUNK
        rows = np.empty((exps.shape[0], min(step, hw)), np.float32)
        pw = np.empty((3, deg + 1, min(step, hw)), np.float32)
        scale = np.float32(1 / COLOUR_SCALE)
        for f in range(frames.shape[0]):
            for s in range(0, hw, step):
                e = min(s + step, hw)
                n = e - s
                pw[:, 0, :n] = 1.0
                np.multiply(frames[f, s:e].T, scale, out=pw[:, 1, :n])
                for d in range(2, deg + 1):
                    np.multiply(pw[:, d - 1, :n], pw[:, 1, :n], out=pw[:, d, :n])
                for t, (e0, e1, e2) in enumerate(exps):
                    np.multiply(pw[0, e0, :n], pw[1, e1, :n], out=rows[t, :n])
                    if e2:
                        rows[t, :n] *= pw[2, e2, :n]
                m = coef_t @ rows[:, :n]  # (2 Tp, n)
                b = basis[:, s:e]
                acc = m[0:2] * b[0]
                for j in range(1, b.shape[0]):
                    m[2 * j:2 * j + 2] *= b[j]
                    acc += m[2 * j:2 * j + 2]
                out[f, s:e] = acc.T
        return out.reshape(*diff.shape[:-1], 2)

    def _basis_rows(self, h: int, w: int) -> np.ndarray:
        """(Tp, H W) float32 position monomials of a frame's pixels (cached per size)."""
        cache = self.__dict__.setdefault("_basis", {})
        if (h, w) not in cache:
            _, xy, _ = _flatten(np.zeros((h, w, 3), np.float32))
            cache[(h, w)] = np.ascontiguousarray(
                pos_basis(xy, int(self.params["pos_degree"]), np).T, np.float32)
        return cache[(h, w)]

    def _coef_rows(self) -> np.ndarray:
        """(2 Tp, Tc) float32: the coefficients with row 2 j + k for position term j, output k."""
        c = self.__dict__.get("_coef_t")
        if c is None:
            coef = self.arrays["poly.coef"]
            tc = exponents(int(self.params["degree"]), 3).shape[0]
            c = self.__dict__["_coef_t"] = np.ascontiguousarray(coef.reshape(tc, -1).T)
        return c

    def predict_flat(self, colour: np.ndarray, xy: np.ndarray) -> np.ndarray:
        # sum_ij a_i b_j c_ij = sum_j b_j (A @ C_j): never forms the (N, Tc * Tp) design matrix.
        # Measured on a 480x640 frame (degree 3, position degree 2): 95 ms with the design
        # matrix, see docs/benchmarks.md for this form.
        deg, pdeg = int(self.params["degree"]), int(self.params["pos_degree"])
        z = colour / np.float32(COLOUR_SCALE)
        a = _monomials([z[:, 0], z[:, 1], z[:, 2]], exponents(deg, 3), np)
        b = pos_basis(xy, pdeg, np)
        coef = self.arrays["poly.coef"]  # (Tc * Tp, 2), row i * Tp + j
        m = a @ coef.reshape(a.shape[1], -1)  # (N, Tp * 2)
        out = np.einsum("njk,nj->nk", m.reshape(-1, b.shape[1], 2), b)
        return out.astype(np.float32, copy=False)

    def predict_torch(self, diff: Any) -> Any:
        import torch

        h, w = diff.shape[-3:-1]
        coef = _cached_tensor(self, "poly.coef", diff.device)
        colour = diff.reshape(-1, 3)
        xy = _torch_xy(h, w, diff.device).expand(*diff.shape[:-3], h, w, 2).reshape(-1, 2)
        out = torch.empty((colour.shape[0], 2), dtype=torch.float32, device=diff.device)
        for s in range(0, colour.shape[0], CHUNK * 4):
            sl = slice(s, s + CHUNK * 4)
            out[sl] = self._design(colour[sl], xy[sl], torch) @ coef
        return out.reshape(*diff.shape[:-1], 2)

    @classmethod
    def fit(cls, colour: np.ndarray, xy: np.ndarray, target: np.ndarray, *, degree: int = 3,
            pos_degree: int = 2, ridge: float = 1e-6, **_: Any) -> PolyMapping:
        if not 1 <= degree <= 8 or not 0 <= pos_degree <= 4:
            raise VtsError(f"poly needs 1 <= --degree <= 8 and 0 <= --pos-degree <= 4, got "
                           f"{degree} and {pos_degree}")
        t = exponents(degree, 3).shape[0] * exponents(pos_degree, 2).shape[0]
        ata = np.zeros((t, t))
        atb = np.zeros((t, 2))
        for s in range(0, colour.shape[0], CHUNK):
            a = _poly_design(colour[s:s + CHUNK].astype(np.float64),
                             xy[s:s + CHUNK].astype(np.float64), degree, pos_degree, np)
            ata += a.T @ a
            atb += a.T @ target[s:s + CHUNK].astype(np.float64)
        n = max(colour.shape[0], 1)
        ata += ridge * n * np.eye(t)
        coef = np.linalg.solve(ata, atb)
        return cls({"degree": int(degree), "pos_degree": int(pos_degree),
                    "ridge": float(ridge), "terms": int(t)},
                   {"poly.coef": coef.astype(np.float32)})


# -- mlp --------------------------------------------------------------------------------------


class MlpMapping(Mapping):
    """A SiLU perceptron of the colour whose outputs weight a polynomial basis of the position.

        (p, q) = out_scale * sum_j b_j(x, y) * h_j(dR/64, dG/64, dB/64)

    with b_j the monomials of (x, y) up to `pos_degree` (default 2: 1, x, y, x^2, xy, y^2)
    and h the network's 2 x B outputs. The colour-to-slope relation can bend as it must, while
    the spatial variation stays smooth across gel that no training press reached.
    """

    method = "mlp"

    def _dims(self) -> list[int]:
        n_basis = exponents(int(self.params["pos_degree"]), 2).shape[0]
        n_in = 5 if self.params.get("xy_input") else 3
        return [n_in] + [int(self.params["width"])] * int(self.params["depth"]) + [2 * n_basis]

    def predict_flat(self, colour: np.ndarray, xy: np.ndarray) -> np.ndarray:
        try:  # torch's CPU kernels when present: SiLU in numpy (np.exp) dominates otherwise
            import torch
        except ImportError:
            return self._predict_numpy(colour, xy)
        with torch.no_grad():
            out = self._mlp_torch(torch.from_numpy(np.require(colour, np.float32, "CW")),
                                  torch.from_numpy(np.require(xy, np.float32, "CW")))
        return out.numpy()

    def _predict_numpy(self, colour: np.ndarray, xy: np.ndarray) -> np.ndarray:
        h = (colour / np.float32(COLOUR_SCALE)).astype(np.float32)
        if self.params.get("xy_input"):
            h = np.concatenate([h, xy.astype(np.float32)], axis=1)
        n = int(self.params["depth"]) + 1
        for i in range(n):
            h = h @ self.arrays[f"mlp.{i}.weight"].T + self.arrays[f"mlp.{i}.bias"]
            if i < n - 1:
                h = h / (1 + np.exp(-h))  # SiLU
        basis = pos_basis(xy, int(self.params["pos_degree"]), np).astype(np.float32)
        out = np.einsum("nbk,nb->nk", h.reshape(h.shape[0], -1, 2), basis)
        return (out * self.arrays["mlp.out_scale"]).astype(np.float32)

    def predict_torch(self, diff: Any) -> Any:
        h_, w_ = diff.shape[-3:-1]
        xy = _torch_xy(h_, w_, diff.device).expand(*diff.shape[:-3], h_, w_, 2).reshape(-1, 2)
        return self._mlp_torch(diff.reshape(-1, 3), xy).reshape(*diff.shape[:-1], 2)

    def _mlp_torch(self, colour: Any, xy: Any) -> Any:
        """(N, 2) gradients of (N, 3) colour differences at (N, 2) positions, in torch."""
        import torch

        dev = colour.device
        h = colour / COLOUR_SCALE
        if self.params.get("xy_input"):
            h = torch.cat([h, xy], dim=1)
        n = int(self.params["depth"]) + 1
        for i in range(n):
            wt = _cached_tensor(self, f"mlp.{i}.weight", dev)
            b = _cached_tensor(self, f"mlp.{i}.bias", dev)
            h = torch.nn.functional.linear(h, wt, b)
            if i < n - 1:
                h = torch.nn.functional.silu(h)
        basis = pos_basis(xy, int(self.params["pos_degree"]), torch)
        out = torch.einsum("nbk,nb->nk", h.reshape(h.shape[0], -1, 2), basis)
        return out * _cached_tensor(self, "mlp.out_scale", dev)

    @classmethod
    def fit(cls, colour: np.ndarray, xy: np.ndarray, target: np.ndarray, *, width: int = 32,
            depth: int = 3, pos_degree: int = 2, xy_input: bool = False, epochs: int = 40,
            lr: float = 3e-3, batch_size: int = 4096, seed: int = 0, device: str | None = "auto",
            **_: Any) -> MlpMapping:
        try:
            import torch
        except ImportError:
            raise VtsError("--method mlp needs torch (pip install 'vtsbench[torch]'); "
                           "lut and poly do not") from None
        if not (1 <= width <= 4096 and 1 <= depth <= 32 and 1 <= epochs <= 100_000
                and 0 <= pos_degree <= 4):
            raise VtsError(f"mlp needs 1 <= --width <= 4096, 1 <= --depth <= 32, 1 <= --epochs "
                           f"<= 100000 and 0 <= pos_degree <= 4, got {width}, {depth}, {epochs}, "
                           f"{pos_degree}")
        dev = torch.device(resolve_device(device) or "cpu")
        params = {"width": int(width), "depth": int(depth), "pos_degree": int(pos_degree),
                  "xy_input": bool(xy_input),
                  "epochs": int(epochs), "lr": float(lr), "batch_size": int(batch_size),
                  "activation": "silu", "seed": int(seed), "trained_on": dev.type}
        probe = cls(params, {})
        dims = probe._dims()
        gen = torch.Generator().manual_seed(int(seed))
        layers: list[torch.nn.Module] = []
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(int(seed))
            for i in range(len(dims) - 1):
                layers.append(torch.nn.Linear(dims[i], dims[i + 1]))
                if i < len(dims) - 2:
                    layers.append(torch.nn.SiLU())
        net = torch.nn.Sequential(*layers).to(dev)
        out_scale = np.maximum(target.std(axis=0), 1e-3).astype(np.float32)
        x_np = colour / np.float32(COLOUR_SCALE)
        if xy_input:
            x_np = np.concatenate([x_np, xy], axis=1)
        x_all = torch.from_numpy(x_np.astype(np.float32)).to(dev)
        b_all = torch.from_numpy(pos_basis(xy.astype(np.float32), pos_degree, np)).to(dev)
        y_all = torch.from_numpy((target / out_scale).astype(np.float32)).to(dev)
        n = x_all.shape[0]
        steps = max(1, math.ceil(n / batch_size))
        opt = torch.optim.Adam(net.parameters(), lr=lr)
        sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=lr, total_steps=epochs * steps,
                                                    pct_start=0.15)
        net.train()
        # Small layers: one CPU thread is faster than two (no spinning, no sharing with other
        # work) and gives the same result on any machine.
        threads = torch.get_num_threads()
        if dev.type == "cpu":
            torch.set_num_threads(1)
        try:
            _train(net, x_all, b_all, y_all, opt, sched, epochs, steps, batch_size, gen, dev)
        finally:
            torch.set_num_threads(threads)
        arrays: dict[str, np.ndarray] = {"mlp.out_scale": out_scale}
        linears = [m for m in net if isinstance(m, torch.nn.Linear)]
        for i, lin in enumerate(linears):
            arrays[f"mlp.{i}.weight"] = lin.weight.detach().cpu().numpy()
            arrays[f"mlp.{i}.bias"] = lin.bias.detach().cpu().numpy()
        return cls(params, arrays)


def _train(net: Any, x_all: Any, b_all: Any, y_all: Any, opt: Any, sched: Any, epochs: int,
           steps: int, batch_size: int, gen: Any, dev: Any) -> None:
    """Mini-batch epochs over shuffled samples: mean squared error of the scaled gradients."""
    import torch

    n = x_all.shape[0]
    for _ in range(int(epochs)):
        perm = torch.randperm(n, generator=gen).to(dev)
        for s in range(steps):
            idx = perm[s * batch_size:(s + 1) * batch_size]
            h = net(x_all[idx]).reshape(idx.shape[0], -1, 2)
            pred = torch.einsum("nbk,nb->nk", h, b_all[idx])
            loss = torch.nn.functional.mse_loss(pred, y_all[idx])
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            sched.step()


# -- shared -----------------------------------------------------------------------------------

CLASSES: dict[str, type[Mapping]] = {"lut": LutMapping, "poly": PolyMapping, "mlp": MlpMapping}


def resolve_device(device: str | None) -> str | None:
    """None stays None; "auto" is "cuda" when torch sees a GPU, else None; else as given."""
    if device is None:
        return None
    if device == "auto":
        try:
            import torch
        except ImportError:
            return None
        return "cuda" if torch.cuda.is_available() else None
    return device


def _torch_xy(h: int, w: int, device: Any) -> Any:
    import torch

    x, y = norm_xy(h, w)
    xy = np.empty((h, w, 2), np.float32)
    xy[..., 0] = x[None, :]
    xy[..., 1] = y[:, None]
    return torch.from_numpy(xy).to(device)


def _cached_tensor(m: Mapping, name: str, device: Any) -> Any:
    """An array of the mapping as a torch tensor on device, converted once."""
    import torch

    cache = m.__dict__.setdefault("_torch", {})
    key = (name, str(device))
    if key not in cache:
        cache[key] = torch.from_numpy(m.arrays[name]).to(device)
    return cache[key]


def fit_mapping(method: str, colour: np.ndarray, xy: np.ndarray, target: np.ndarray,
                **options: Any) -> Mapping:
    """Fit a mapping of the given method to samples; options are the method's parameters."""
    if method not in CLASSES:
        raise VtsError(f"unknown method {method!r} (use one of {', '.join(METHODS)})")
    if colour.shape[0] == 0:
        raise VtsError("no training samples")
    return CLASSES[method].fit(colour, xy, target, **options)


def mapping_from_arrays(method: str, params: dict[str, Any],
                        arrays: dict[str, np.ndarray]) -> Mapping:
    """Rebuild a mapping from its parameters and arrays (as stored in a calibration file)."""
    if method not in CLASSES:
        raise VtsError(f"unknown mapping method {method!r}")
    m = CLASSES[method](params, arrays)
    _validate(m)
    return m


def _validate(m: Mapping) -> None:
    """Raise ValueError if the arrays do not fit the parameters."""
    if isinstance(m, LutMapping):
        t = m.arrays.get("lut.table")
        b = int(m.params["bins"])
        cy, cx = (int(v) for v in m.params["cells"])
        if t is None or t.shape != (cy, cx, b, b, b, 2):
            raise ValueError("lut table missing or of the wrong shape")
        if not float(m.params["hi"]) > float(m.params["lo"]):
            raise ValueError("lut range empty")
    elif isinstance(m, PolyMapping):
        t = exponents(int(m.params["degree"]), 3).shape[0] * \
            exponents(int(m.params["pos_degree"]), 2).shape[0]
        c = m.arrays.get("poly.coef")
        if c is None or c.shape != (t, 2):
            raise ValueError("poly coefficients missing or of the wrong shape")
    else:
        dims = m._dims()  # type: ignore[attr-defined]
        for i in range(len(dims) - 1):
            wt, b = m.arrays.get(f"mlp.{i}.weight"), m.arrays.get(f"mlp.{i}.bias")
            if wt is None or b is None or wt.shape != (dims[i + 1], dims[i]) or \
                    b.shape != (dims[i + 1],):
                raise ValueError(f"mlp layer {i} missing or of the wrong shape")
        if m.arrays.get("mlp.out_scale", np.zeros(0)).shape != (2,):
            raise ValueError("mlp output scale missing")
