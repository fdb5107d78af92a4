"""Square crops of a sequence around where the gel is touched, for models that need the
resolution where the contact is (the slip TimeSformer recipe).

The centre comes from the sequence itself, never from a label: the union of its contact masks
(a dataset built with depth), else where the frames change most against the first one, else the
frame's centre. The crop is `crop_px` sensor pixels on a side (shifted inside the frame), resized
to `size`: an isotropic square, so quarter turns of it keep slip-direction labels exact.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: Grey levels of (blurred) change against the first frame below which a pixel counts as still.
MOTION_LEVEL = 4.0


def crop_center(rgb: np.ndarray, contact: np.ndarray | None = None) -> tuple[float, float]:
    """(x, y) in pixels of the crop centre of a (T, H, W, 3) uint8 sequence."""
    import cv2

    h, w = rgb.shape[1:3]
    if contact is not None:
        m = np.asarray(contact).any(axis=0)
        if m.any():
            ys, xs = np.nonzero(m)
            return float(xs.mean()), float(ys.mean())
    if len(rgb) < 2:
        return (w - 1) / 2.0, (h - 1) / 2.0
    g = rgb.mean(axis=-1, dtype=np.float32)
    energy = cv2.GaussianBlur(np.abs(g[1:] - g[:1]).max(axis=0), (0, 0), 3.0)
    energy[energy < MOTION_LEVEL] = 0.0
    total = float(energy.sum())
    if total <= 0.0:
        return (w - 1) / 2.0, (h - 1) / 2.0
    ys, xs = np.mgrid[0:h, 0:w]
    return float((xs * energy).sum() / total), float((ys * energy).sum() / total)


def crop_box(center: tuple[float, float], crop_px: int, shape: tuple[int, int]
             ) -> tuple[int, int, int]:
    """(x0, y0, side) of a square of side min(crop_px, H, W) around center, inside the frame."""
    h, w = shape
    side = int(min(crop_px, h, w))
    x0 = round(center[0] - side / 2)
    y0 = round(center[1] - side / 2)
    return min(max(x0, 0), w - side), min(max(y0, 0), h - side), side


def crop_sequence(frames: np.ndarray, box: tuple[int, int, int], size: int) -> np.ndarray:
    """(T, H, W[, C]) frames cut to box and resized (area) to size x size; dtype kept."""
    import cv2

    x0, y0, side = box
    out = []
    for f in frames:
        c = np.ascontiguousarray(f[y0:y0 + side, x0:x0 + side])
        out.append(cv2.resize(c, (size, size), interpolation=cv2.INTER_AREA)
                   if side != size else c)
    return np.stack(out)


#: Flow channels: each flow vector, in pixels at the model's input, keeps its angle and has its
#: length compressed to tanh(length / FLOW_SOFT_PX) (`compress_flow`). The earlier linear
#: scaling (divided by 16 px, clipped to [-1, 1]) left a 0.08 mm slip (0.7 px at a 256-pixel
#: crop resized to 64) at 0.04, lost beside frames of unit range, and per-axis clipping bends
#: a large slip's angle towards the diagonal; the soft radial compression does neither.
FLOW_SOFT_PX = 2.0


def compress_flow(f: np.ndarray, soft_px: float = FLOW_SOFT_PX) -> np.ndarray:
    """(..., 2, H, W) flow in pixels -> the same angles, lengths tanh(length / soft_px) in
    [0, 1): small slips readable, large ones unclipped in angle."""
    mag = np.hypot(f[..., 0, :, :], f[..., 1, :, :])[..., None, :, :]
    gain = np.where(mag > 1e-6, np.tanh(mag / soft_px) / np.maximum(mag, 1e-6), 1.0 / soft_px)
    return (f * gain).astype(np.float32)


def crop_flow(grey: np.ndarray, size: int) -> np.ndarray:
    """(T, 2, size, size) float32: DIS optical flow (OpenCV, `medium` preset) from the first
    frame to each frame of a (T, S, S) uint8 crop, resized to size, in pixels at that size,
    radially compressed (`compress_flow`; x right, y down the rows). Frame 0: 0."""
    import cv2

    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    side = grey.shape[-1]
    out = np.zeros((len(grey), 2, size, size), np.float32)
    for t in range(1, len(grey)):
        f = dis.calc(grey[0], grey[t], None)
        f = cv2.resize(f, (size, size), interpolation=cv2.INTER_AREA) * (size / side)
        out[t] = compress_flow(f.transpose(2, 0, 1))
    return out


FLOWS = ("dis", "shift")


def _grey(sample: dict[str, Any], modality: str, box: tuple[int, int, int]) -> np.ndarray:
    """(T, side, side) uint8 grey levels inside box at sensor resolution, what the motion
    channels are measured on: the frames' grey, or for depth alone the depth maps scaled from
    0 to the deepest point in the box."""
    import cv2

    if modality == "depth":
        d = crop_sequence(np.asarray(sample["depth"], dtype=np.float32), box, box[2])
        return np.clip(255 * d / max(float(d.max()), 1e-6), 0, 255).astype(np.uint8)
    return np.stack([cv2.cvtColor(f, cv2.COLOR_RGB2GRAY)
                     for f in crop_sequence(sample["rgb"], box, box[2])])


#: Side (sensor px) of the square around the contact where the `shift` channels are measured:
#: the whole moving imprint, also when it is larger than the model's crop. On the demo's
#: slipping sequences (unseen_objects, train / test) the phase correlation of the first and last
#: frame bins right 96 / 84 % at a 256 px square, 96 / 95 % at 384, 97 / 97 % at 480.
MOTION_PX = 480


def contact_mask(sample: dict[str, Any], box: tuple[int, int, int], size: int) -> np.ndarray:
    """(size, size) float32: 1 where the gel is in contact in any frame of the sample inside
    box (its `contact` masks), 0 elsewhere; all ones when the sample has no contact masks."""
    c = sample.get("contact")
    if c is None:
        return np.ones((size, size), np.float32)
    union = np.asarray(c, dtype=bool).any(axis=0)[None].astype(np.float32)
    return (crop_sequence(union, box, size)[0] > 0.0).astype(np.float32)


def contact_crop(sample: dict[str, Any], crop_px: int, size: int, modality: str,
                 flow: str | None = None, soft_px: float = FLOW_SOFT_PX,
                 flow_mask: bool = False) -> tuple[np.ndarray, tuple[float, float]]:
    """A sample's sequence cut around its contact: (T, C, size, size) float32 (rgb in [0, 1],
    then depth in mm for rgbd; depth alone for depth; with `flow`, two more channels of motion
    from the first frame: `shift`, the phase-correlation displacement of the moving gel drawn
    over where it moves (`vtsbench.transforms.motion.shift_field`), or `dis`, the dense DIS optical
    flow of the crop (`crop_flow`), both in pixels at the model's input, radially compressed)
    and the model-input pixels per sensor pixel (x, y). `soft_px`: the length (pixels at the
    model's input) where the compression of the `shift` channels bends (`compress_flow`).
    `flow_mask`: the `dis` channels kept only where the gel is in contact (`contact_mask`), so
    that the still gel and its fixed pattern (zero flow) do not dilute the imprint's motion."""
    if flow not in (None, *FLOWS):
        raise ValueError(f"flow must be one of {FLOWS} or None, not {flow!r}")
    rgb = sample["rgb"]
    center = crop_center(rgb, sample.get("contact"))
    box = crop_box(center, crop_px, rgb.shape[1:3])
    parts = []
    if modality in ("rgb", "rgbd"):
        parts.append(crop_sequence(rgb, box, size).astype(np.float32).transpose(0, 3, 1, 2)
                     / 255.0)
    if modality in ("depth", "rgbd"):
        d = crop_sequence(np.asarray(sample["depth"], dtype=np.float32), box, size)
        parts.append(d[:, None])
    scale = size / box[2]
    if flow == "dis":
        fl = crop_flow(_grey(sample, modality, box), size)
        if flow_mask:
            fl *= contact_mask(sample, box, size)[None, None]
        parts.append(fl)
    elif flow == "shift":
        from vtsbench.transforms.motion import shift_field

        # a larger square around the same centre, which holds `box` (both inside the frame)
        x0, y0, side = crop_box(center, max(MOTION_PX, crop_px), rgb.shape[1:3])
        field = shift_field(_grey(sample, modality, (x0, y0, side))).transpose(0, 2, 3, 1)
        cut = crop_sequence(field, (box[0] - x0, box[1] - y0, box[2]), size)  # sensor px
        parts.append(compress_flow(cut.transpose(0, 3, 1, 2) * scale, soft_px))
    return np.concatenate(parts, axis=1), (scale, scale)

