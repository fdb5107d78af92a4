"""Depth and contact of a shard's frames: the build's path through the calibration, frame by frame.

`DepthMaker(calibration).depth(rgb, solver)` gives the same float32 depth as
`vtsbench.depth.reconstruct.reconstruct(rgb, calibration, solver=solver)` for "dct" and "dst",
bit for bit (the same float32 operations in the same order; tests/depth/test_build_depth.py),
but one frame at a time in preallocated buffers, without the copies and dtype conversions the
general path makes between the colour difference, the mapping and the solver, and with one FFT
thread. The "masked" solver goes through `vtsbench.depth.poisson.integrate` with the contact
mask.

Measured at 480x640 on one core of a 2-core AMD EPYC (lut + dct): 12.9 ms a frame through
`reconstruct`, 5.2 ms here (colour difference 1.2, lut 0.9, integration 3.1 of which the two
DCTs 1.9). What differs:

- lut lookup: the table index comes from a per-pixel cell offset computed once and the colour
  bins combined by one cv2.transform (exact: every intermediate of the float32 index is an
  integer below 2^24), and the two gradients of an entry are read as one 8-byte word
  (np.take): 5.6 -> 1.1 ms;
- the zero-difference test (`still`) is skipped when the calibration's zero map equals the
  mapping at a zero difference (then a still pixel gets exactly 0 anyway): 0.7 ms; and the
  zero map is then taken off inside the table, once per entry, instead of off every frame
  (`_fold_zero`): 1.37 -> 0.90 ms for the gradients;
- the divergence is formed from the interleaved gradients with out= operations, without the
  finite checks (the lut's values are checked once) and the staggered copies, the x
  differences on the flattened rows (contiguous): 1.9 -> 0.8 ms.

The contact mask is made from the same blurred colour difference (`contact`): its Euclidean
distance to the background over the channels above CONTACT_PARAMS threshold, cleaned at full
resolution by `vtsbench.depth.mask.clean_mask` (OpenCV): 0.8 ms a frame.

On a marker gel (the calibration's `markers`) each frame goes through the calibration's own
dot handling, as `Calibration.gradients`: `difference` takes the dots out with the gain and
offset of `Calibration.dots` before the blur, and `gradients` fills that frame's fill mask
(`markers.fill_gradients`); the contact is then made from the corrected difference. A plain gel
takes none of this.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: Colour distance (fraction of 255) above which a pixel is in contact, and the cleaning of
#: vtsbench.depth.mask.clean_mask: mask_from_images' defaults, at full resolution.
CONTACT_PARAMS = {"threshold": 0.04, "close_px": 3, "min_area_px": 20, "dilate_px": 2}
#: cv2.transform's weights that sum the three channels.
_ONES = np.ones((1, 3), np.float32)


class DepthMaker:
    """Depth (mm, float32) and contact (bool) of RGB frames for one calibration (reusable)."""

    def __init__(self, cal: Any) -> None:
        from .mapping import LutMapping, norm_xy
        from .poisson import border_mask, inverse_eigenvalues, spacing

        self.cal = cal
        h, w = self.shape = cal.resolution
        self.bg = np.ascontiguousarray(cal.background, np.float32)
        self.hx, self.hy = spacing(cal.mm_per_px)
        f32 = np.dtype(np.float32).str
        self.inv = inverse_eigenvalues("dct", h, w, f32, self.hx, self.hy)
        self.inv_dst = inverse_eigenvalues("dst", h, w, f32, self.hx, self.hy)
        self.border = border_mask(h, w)
        # its pixels' flat indices, in the order boolean indexing takes them (0.17 -> 0.03 ms)
        self.border_idx = np.flatnonzero(self.border)
        self.diff = np.empty((h, w, 3), np.float32)
        # the divergence's parts; `b` then holds the transforms and the depth, in place
        # zeros: the flattened x pass reads ax's last element before it is first written
        self.ax, self.ay, self.b = (np.zeros((h, w), np.float32) for _ in range(3))
        self.p, self.q = np.empty((h, w), np.float32), np.empty((h, w), np.float32)
        self.lut: dict[str, Any] | None = None
        #: fill mask (H, W) of the marker-gel frame last passed to `difference`; None: no dots
        self.fill: np.ndarray | None = None
        m = cal.mapping
        if isinstance(m, LutMapping):
            cy, cx, b = m.table.shape[0], m.table.shape[1], m.table.shape[2]
            if cy * cx * b**3 < 2**24 and np.isfinite(m.table).all():
                lo, hi = float(m.params["lo"]), float(m.params["hi"])
                x, y = norm_xy(h, w)
                # as LutMapping._index computes the cell of a position, in float32
                jx = np.clip(np.floor((x + 1) * (cx / 2)), 0, cx - 1).astype(np.int32)
                jy = np.clip(np.floor((y + 1) * (cy / 2)), 0, cy - 1).astype(np.int32)
                cell = (jy[:, None] * cx + jx[None, :]) * b**3
                table = np.ascontiguousarray(m.table, np.float32).reshape(-1, 2)
                self.lut = {"lo": np.float32(lo), "scale": np.float32(b / (hi - lo)),
                            "b": b, "cell": cell.astype(np.float32),
                            "weights": np.array([[b * b, b, 1]], np.float32),
                            "words": table.view(np.uint64).reshape(-1),
                            "k": np.empty((h, w, 3), np.float32),
                            # np.intp: np.take would cast any other index type (0.15 ms)
                            "idx": np.empty((h, w), np.intp)}
        self.still_is_zero = self._still_is_zero()
        if self.lut is not None and self.still_is_zero:
            self.lut["zero_folded"] = self._fold_zero()

    def _fold_zero(self) -> bool:
        """Take the zero map off inside the lut instead of off every frame (0.37 ms a frame).

        With a lut the zero map is f(0, x, y): in each pixel's cell, the table entry of a zero
        difference (still_is_zero checked that it equals the calibration's zero map). So
        subtracting that entry from every entry of the cell gives, entry by entry, the same
        float32 difference `gradients` computes pixel by pixel: bit for bit the same result.
        False (nothing changed) when a cell's pixels disagree on their zero entry.
        """
        lut = self.lut
        n = lut["b"] ** 3
        self._gradients_of(np.zeros((*self.shape, 3), np.float32))
        idx = lut["idx"].reshape(-1)
        cells = np.floor_divide(lut["cell"].reshape(-1), n).astype(np.int64)
        zero_of = np.full(len(lut["words"]) // n, -1, np.int64)
        zero_of[cells] = idx
        if not np.array_equal(zero_of[cells], idx):
            return False
        table = lut["words"].view(np.float32).reshape(-1, n, 2).copy()
        for c, z in enumerate(zero_of):
            if z >= 0:
                table[c] -= table[z // n, z % n].copy()
        lut["words"] = table.reshape(-1, 2).view(np.uint64).reshape(-1)
        return True

    @property
    def zero_folded(self) -> bool:
        """Whether the lut in use has the zero map taken off already (_fold_zero)."""
        return self.lut is not None and bool(self.lut.get("zero_folded"))

    def _still_is_zero(self) -> bool:
        """True when a zero colour difference maps exactly to the zero map (then the general
        path's `g[still] = 0` changes nothing)."""
        zero = np.zeros((*self.shape, 3), np.float32)
        return bool(np.array_equal(self._gradients_of(zero), self.cal.zero_map))

    def _gradients_of(self, diff: np.ndarray) -> np.ndarray:
        """f(diff, x, y) (H, W, 2) float32, before the zero map is taken off."""
        lut = self.lut
        if lut is None:
            return self.cal.mapping.predict(diff)
        import cv2

        k, idx, b = lut["k"], lut["idx"], lut["b"]
        np.subtract(diff, lut["lo"], out=k)
        np.multiply(k, lut["scale"], out=k)
        # clip(floor(v), 0, b - 1) == trunc(clip(v, 0, b - 1)) for every finite v
        np.clip(k, 0, b - 1, out=k)
        np.trunc(k, out=k)
        # the bins' share of the index, in float32: exact (integers below 2^24) whatever the
        # order or fused multiply-adds OpenCV uses; 0.6 ms faster than int32 numpy operations
        flat = cv2.transform(k, lut["weights"])
        flat += lut["cell"]
        idx[...] = flat
        return np.take(lut["words"], idx).view(np.float32).reshape(*self.shape, 2)

    def difference(self, rgb: np.ndarray) -> np.ndarray:
        """The calibration's colour difference of one frame (H, W, 3), in self.diff; on a marker
        gel divided by the dots' transmission, with the frame's fill mask kept in self.fill for
        `gradients` (Calibration.dots)."""
        import cv2

        cal, d = self.cal, self.diff
        # the same float32 values as np.subtract(rgb, bg, dtype=np.float32) (uint8 -> float32 is
        # exact), without numpy's buffered casting of mixed types: 0.30 -> 0.23 ms
        cv2.subtract(rgb, self.bg, dst=d, dtype=cv2.CV_32F)
        if cal.markers is not None:  # as colour_difference: the dots out, then blurred
            from .markers import blur_difference

            dots = cal.dots(rgb)
            self.fill = dots.fill
            dots.apply(d)
            d[...] = blur_difference(d, cal.blur_px, dots.blur_weight, dots.wide_px)
        elif cal.blur_px > 0:
            cv2.GaussianBlur(d, (0, 0), cal.blur_px, dst=d, borderType=cv2.BORDER_REFLECT_101)
        np.clip(d, -cal.colour_limit_dn, cal.colour_limit_dn, out=d)
        return d

    def gradients(self, diff: np.ndarray) -> np.ndarray:
        """(p, q) of one frame (H, W, 2) float32, as Calibration.gradients (on a marker gel:
        diff from `difference`, whose frame's fill mask is filled here)."""
        g = self._gradients_of(diff)
        if not self.zero_folded:
            g -= self.cal.zero_map
        if not self.still_is_zero:
            still = (diff[..., 0] == 0) & (diff[..., 1] == 0) & (diff[..., 2] == 0)
            if still.any():
                g[still] = 0.0
        if self.fill is not None and self.fill.any():
            from .markers import fill_gradients

            g[...] = fill_gradients(g, self.fill)
        return g

    def integrate(self, g: np.ndarray, solver: str, mask: np.ndarray | None = None
                  ) -> np.ndarray:
        """vtsbench.depth.poisson.integrate(p, q, method=solver, sampling="point") of one frame,
        float32: "dct" and "dst" with the same operations in the same order, in place (the
        result is overwritten by the next call) and on one FFT thread; "masked" through
        integrate itself (mask: the contact)."""
        import cv2
        import scipy.fft

        if solver == "masked":
            from .poisson import integrate

            return integrate(g[..., 0], g[..., 1], method="masked", mask=mask,
                             mm_per_px=self.cal.mm_per_px, dtype=np.float32)
        dct = solver == "dct"
        # p and q apart (contiguous): the arithmetic on them is then about twice as fast as on
        # the interleaved views, for 0.06 ms of splitting
        p, q = cv2.split(g, [self.p, self.q])
        hx, hy = np.float32(self.hx), np.float32(self.hy)
        ax, ay, b = self.ax, self.ay, self.b
        # staggered(p, q, "point"), then divergence(gx, gy, hx, hy, "neumann" or "dirichlet").
        # Along x on the flattened rows, contiguous (0.4 -> 0.15 ms): the last column then
        # holds a row's end plus the next row's start, and is overwritten below.
        pf, axf = p.reshape(-1), ax.reshape(-1)
        np.add(pf[:-1], pf[1:], out=axf[:-1])
        ax *= np.float32(0.5)
        np.divide(ax, hx, out=ax)
        np.add(q[:-1], q[1:], out=ay[:-1])
        ay[:-1] *= np.float32(0.5)
        np.divide(ay[:-1], hy, out=ay[:-1])
        if dct:  # no edge crosses the border
            ax[:, -1] = 0.0
            ay[-1] = 0.0
        else:  # the edge to the ghost ring keeps the pixel's own slope
            np.divide(p[:, -1], hx, out=ax[:, -1])
            np.divide(q[-1], hy, out=ay[-1])
        np.negative(ax, out=b)
        b -= ay
        if dct:  # flattened too: column 0 gets the previous row's last edge, 0 (0.14 -> 0.04 ms)
            b.reshape(-1)[1:] += axf[:-1]
        else:
            b[:, 1:] += ax[:, :-1]
        b[1:, :] += ay[:-1, :]
        if not dct:
            s = scipy.fft.dstn(b, type=1, norm="ortho", workers=1, overwrite_x=True)
            s *= self.inv_dst
            return scipy.fft.idstn(s, type=1, norm="ortho", workers=1, overwrite_x=True)
        s = scipy.fft.dctn(b, type=2, norm="ortho", workers=1, overwrite_x=True)
        s *= self.inv
        z = scipy.fft.idctn(s, type=2, norm="ortho", workers=1, overwrite_x=True)
        z -= np.median(np.take(z, self.border_idx))  # the border pixels' median at 0 depth
        return z

    def depth(self, rgb: np.ndarray, solver: str = "dct") -> np.ndarray:
        """Depth (H, W) float32 mm of one RGB frame, as reconstruct(rgb, cal, solver=solver)
        for "dct" and "dst" (a new array)."""
        return self.integrate(self.gradients(self.difference(rgb)), solver).copy()

    def contact(self, diff: np.ndarray) -> np.ndarray:
        """Contact mask (H, W) bool of a frame's colour difference (self.difference): the
        Euclidean distance over the channels above CONTACT_PARAMS threshold (x 255 DN), cleaned
        as vtsbench.depth.mask.clean_mask."""
        import cv2

        from .mask import clean_mask

        p = CONTACT_PARAMS
        sq = cv2.multiply(diff, diff)  # squares, exact as numpy's: 0.1 ms against 1.4 (einsum)
        # (r + g) + b in float32 as numpy sums the interleaved channels, in one pass: the
        # weights are 1, so every product is exact and the sums are those of two additions
        # (tests/depth/test_build_depth.py): 0.9 ms against 2.4 ms for splitting and adding the
        # channels, on 400 frames at 480x640
        d2 = cv2.transform(sq, _ONES)
        raw = d2 > np.float32((p["threshold"] * 255.0) ** 2)
        return clean_mask(raw, close_px=p["close_px"], min_area_px=p["min_area_px"],
                          dilate_px=p["dilate_px"])
