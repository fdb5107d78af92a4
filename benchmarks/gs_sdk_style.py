"""A gs_sdk-style depth reconstruction, for timing vtsbench against it on the same machine.

gs_sdk (GelSight's SDK) reconstructs depth from one frame as its `Reconstructor.get_surface_info`
publishes it: a 5-32-32-32-2 MLP (fully connected, batch norm, ReLU) of (B, G, R, x, y) per
pixel in torch, giving the gradient angles; tan, minus the background's gradients; a DCT Poisson
solve with Neumann borders (scipy, float64, its eigenvalue grid built on each call); and a
contact mask (colour distance to the background above a threshold, dilated 7x7, eroded 15x15,
and depth above the 85th percentile less 0.2 mm). gs_sdk itself is not installable here; this
follows its published code path step by step with untrained weights (the speed does not depend
on them). Torch runs on 2 threads, as gs_sdk's CPU path would on a 2-core machine.
"""

from __future__ import annotations

import math

import numpy as np


class GsSdkStyle:
    """The reference pipeline for frames of one size, with its background frame (BGR order)."""

    def __init__(self, background_rgb: np.ndarray, mm_per_px: float, threads: int = 2) -> None:
        import torch

        torch.set_num_threads(threads)
        self.torch = torch
        torch.manual_seed(0)
        layers: list[torch.nn.Module] = []
        for i, o in ((5, 32), (32, 32), (32, 32)):
            layers += [torch.nn.Linear(i, o), torch.nn.BatchNorm1d(o), torch.nn.ReLU()]
        self.net = torch.nn.Sequential(*layers, torch.nn.Linear(32, 2)).eval()
        self.ppmm = 1.0 / mm_per_px
        self.bg_image = background_rgb[..., ::-1].astype(np.float32)
        self.bg_g = self._gradients(self.bg_image)

    def _gradients(self, image: np.ndarray) -> np.ndarray:
        h, w = image.shape[:2]
        xx, yy = np.meshgrid(np.arange(w), np.arange(h))
        xys = np.dstack([xx / w, yy / h]).astype(np.float32)
        bgrxys = np.concatenate([image / 255.0, xys], axis=2).reshape(-1, 5)
        with self.torch.no_grad():
            angles = self.net(self.torch.from_numpy(bgrxys.astype(np.float32))).numpy()
        return np.tan(angles.reshape(h, w, 2))

    def surface(self, frame_rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(depth mm, contact mask) of one RGB frame."""
        import cv2

        image = frame_rgb[..., ::-1].astype(np.float32)
        g = self._gradients(image) - self.bg_g
        depth = poisson_dct_neumann(g[..., 0], g[..., 1]).astype(np.float32) / self.ppmm
        diff = image - self.bg_image
        colour = (np.linalg.norm(diff, axis=-1) > 15).astype(np.uint8)
        colour = cv2.dilate(colour, np.ones((7, 7), np.uint8))
        colour = cv2.erode(colour, np.ones((15, 15), np.uint8))
        cutoff = np.percentile(depth, 85) - 0.2
        return depth, (colour > 0) & (depth < cutoff)


def poisson_dct_neumann(gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
    """gs_sdk's Neumann DCT solve: central differences, border terms, DCT per axis (float64)."""
    import scipy.fft as fft

    h, w = gx.shape
    gxx = gx[:, [*list(range(1, w)), w - 1]] - gx[:, [0, *list(range(w - 1))]]
    gyy = gy[[*list(range(1, h)), h - 1], :] - gy[[0, *list(range(h - 1))], :]
    f = (gxx + gyy).astype(np.float64)
    b = np.zeros(gx.shape)
    b[0, 1:-2] = -gy[0, 1:-2]
    b[-1, 1:-2] = gy[-1, 1:-2]
    b[1:-2, 0] = -gx[1:-2, 0]
    b[1:-2, -1] = gx[1:-2, -1]
    s = 1 / np.sqrt(2)
    b[0, 0] = s * (-gy[0, 0] - gx[0, 0])
    b[0, -1] = s * (-gy[0, -1] + gx[0, -1])
    b[-1, -1] = s * (gy[-1, -1] + gx[-1, -1])
    b[-1, 0] = s * (gy[-1, 0] - gx[-1, 0])
    f[0, 1:-2] -= b[0, 1:-2]
    f[-1, 1:-2] -= b[-1, 1:-2]
    f[1:-2, 0] -= b[1:-2, 0]
    f[1:-2, -1] -= b[1:-2, -1]
    f[0, -1] -= s * b[0, -1]
    f[-1, -1] -= s * b[-1, -1]
    f[-1, 0] -= s * b[-1, 0]
    f[0, 0] -= s * b[0, 0]
    tt = fft.dct(f, norm="ortho")
    fcos = fft.dct(tt.T, norm="ortho").T
    x, y = np.meshgrid(range(1, w + 1), range(1, h + 1), copy=True)
    denom = 4 * (np.sin(0.5 * math.pi * x / w) ** 2 + np.sin(0.5 * math.pi * y / h) ** 2)
    f = -fcos / denom
    tt = fft.idct(f, norm="ortho")
    img = fft.idct(tt.T, norm="ortho").T
    return img.mean() + img
