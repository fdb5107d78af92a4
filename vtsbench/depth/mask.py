"""Contact masks for the masked Poisson solver, from gradients or from colour differences.

Both estimators threshold a per-pixel signal and then clean the result frame by frame:

1. threshold: |grad| = hypot(p, q) > threshold (a slope), or the colour distance to the
   no-contact background > threshold (a fraction of full scale);
2. closing with a disc of radius close_px joins the ring a rounded contact leaves (its flat top
   has near-zero slope) and bridges one- or two-pixel gaps in its outline;
3. hole filling (scipy.ndimage.binary_fill_holes) fills the flat top and any enclosed dimple;
4. specks smaller than min_area_px pixels (4-connected components) are dropped: noise;
5. dilation by dilate_px pixels: the masked solver holds every pixel outside the mask at zero
   depth, so the mask has to reach a little beyond the contact, onto gel that is truly flat.
   Without it the rim pixel, whose slope is large, sits right next to a forced zero and the
   reconstruction loses the rim's step (measured in tests/test_poisson.py).

The morphology pads the frame by the structuring element's reach, so a contact touching the
border is neither eroded nor glued to it.
"""

from __future__ import annotations

import functools

import numpy as np
from scipy import ndimage


@functools.lru_cache(maxsize=16)
def disc(radius: int) -> np.ndarray:
    """A boolean disc of the given pixel radius (a 1x1 True for radius 0)."""
    r = max(int(radius), 0)
    y, x = np.mgrid[-r:r + 1, -r:r + 1]
    d = x * x + y * y <= r * r + r  # the "+ r" rounds the disc like a digitised circle
    d.setflags(write=False)
    return d


def clean_mask(raw: np.ndarray, *, close_px: int = 3, min_area_px: int = 20,
               dilate_px: int = 2) -> np.ndarray:
    """Closing, hole filling, speck removal and dilation of a (..., H, W) boolean mask."""
    raw = np.asarray(raw, bool)
    if raw.ndim < 2:
        raise ValueError(f"expected a mask of shape (..., H, W), got {raw.shape}")
    shape = raw.shape
    frames = raw.reshape(-1, *shape[-2:])
    out = np.empty_like(frames)
    pad = max(int(close_px), 0) + 1
    four = ndimage.generate_binary_structure(2, 1)
    for k, m in enumerate(frames):
        if close_px > 0:
            padded = np.pad(m, pad)
            padded = ndimage.binary_closing(padded, structure=disc(close_px))
            m = padded[pad:-pad, pad:-pad]
        m = ndimage.binary_fill_holes(m)
        if min_area_px > 1 and m.any():
            labels, n = ndimage.label(m, structure=four)
            areas = np.bincount(labels.ravel(), minlength=n + 1)
            keep = areas >= min_area_px
            keep[0] = False
            m = keep[labels]
        if dilate_px > 0 and m.any():
            m = ndimage.binary_dilation(m, structure=disc(dilate_px))
        out[k] = m
    return out.reshape(shape)


def mask_from_gradients(p: np.ndarray, q: np.ndarray, threshold: float = 0.02, *,
                        close_px: int = 3, min_area_px: int = 20,
                        dilate_px: int = 2) -> np.ndarray:
    """Contact mask (..., H, W) bool where the slope |(p, q)| exceeds threshold, cleaned.

    threshold is a slope (mm/mm): 0.02 is about 1.1 degrees, well above the slope noise of a
    calibrated mapping on flat gel and below the rim slope of any press worth measuring.
    """
    p, q = np.asarray(p), np.asarray(q)
    if p.shape != q.shape:
        raise ValueError(f"p and q shapes differ: {p.shape} vs {q.shape}")
    with np.errstate(invalid="ignore"):
        raw = np.hypot(p.astype(np.float64), q.astype(np.float64)) > threshold
    return clean_mask(raw, close_px=close_px, min_area_px=min_area_px, dilate_px=dilate_px)


def _unit_scale(a: np.ndarray) -> np.ndarray:
    if np.issubdtype(a.dtype, np.integer):
        return a.astype(np.float32) / np.float32(np.iinfo(a.dtype).max)
    return a.astype(np.float32)


def mask_from_images(images: np.ndarray, background: np.ndarray, threshold: float = 0.04, *,
                     blur_px: float = 1.0, close_px: int = 3, min_area_px: int = 20,
                     dilate_px: int = 2) -> np.ndarray:
    """Contact mask (..., H, W) bool where frames differ in colour from the no-contact frame.

    images (..., H, W, C) or (..., H, W) (grey) and background of the shape of one frame.
    Integer images are scaled by their type's maximum (uint8: 255) and float images are taken
    as 0..1. The difference is the Euclidean distance over the channels after a Gaussian blur of
    blur_px pixels (suppressing read noise); the default 0.04 is about 10 levels of 8 bits.
    The mask is then cleaned as in clean_mask.
    """
    images, background = np.asarray(images), np.asarray(background)
    if background.ndim not in (2, 3):
        raise ValueError(f"background must be (H, W) or (H, W, C), got {background.shape}")
    if images.shape[images.ndim - background.ndim:] != background.shape:
        raise ValueError(f"images {images.shape} do not end with the background's shape "
                         f"{background.shape}")
    colour = background.ndim == 3
    diff = _unit_scale(images) - _unit_scale(background)
    if blur_px > 0:
        sigma = [0.0] * diff.ndim
        sigma[-3 if colour else -2] = sigma[-2 if colour else -1] = blur_px
        diff = ndimage.gaussian_filter(diff, sigma=sigma, mode="nearest")
    dist = np.sqrt((diff**2).sum(axis=-1)) if colour else np.abs(diff)
    return clean_mask(dist > threshold, close_px=close_px, min_area_px=min_area_px,
                      dilate_px=dilate_px)
