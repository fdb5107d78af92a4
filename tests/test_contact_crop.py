"""Contact crops and the quarter-turn augmentation: the crop follows the moving imprint, and a
turned or mirrored sequence moves in the direction its mapped label says."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from vtsbench.labels import angle_to_class
from vtsbench.models.contact_crop import contact_crop, crop_box, crop_center
from vtsbench.models.timesformer import dihedral_augment


def moving_blob(dx: float, dy_rows: float, t: int = 4, h: int = 60, w: int = 80,
                at: tuple[int, int] = (50, 25)) -> np.ndarray:
    """(T, H, W, 3) uint8: a textured disc moving by (dx, dy_rows) px over the sequence."""
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    out = []
    for k in range(t):
        cx, cy = at[0] + dx * k / (t - 1), at[1] + dy_rows * k / (t - 1)
        r = np.hypot(xs - cx, ys - cy)
        tex = 0.5 + 0.5 * np.sin(0.9 * (xs - cx)) * np.cos(0.7 * (ys - cy))
        img = np.where(r < 9, 60 + 150 * tex, 30)
        out.append(np.repeat(img[..., None], 3, axis=2).astype(np.uint8))
    return np.stack(out)


def test_center_from_contact_then_motion_then_frame() -> None:
    seq = moving_blob(4, 0)
    contact = np.zeros(seq.shape[:3], bool)
    contact[:, 10:20, 5:15] = True
    assert crop_center(seq, contact) == pytest.approx((9.5, 14.5))
    x, y = crop_center(seq, np.zeros_like(contact))
    assert abs(x - 52) < 4 and abs(y - 25) < 3
    still = np.repeat(seq[:1], 4, axis=0)
    assert crop_center(still) == (39.5, 29.5)
    assert crop_center(seq[:1]) == (39.5, 29.5)


def test_box_stays_inside_the_frame() -> None:
    assert crop_box((2.0, 2.0), 20, (60, 80)) == (0, 0, 20)
    assert crop_box((79.0, 59.0), 20, (60, 80)) == (60, 40, 20)
    assert crop_box((40.0, 30.0), 500, (60, 80)) == (10, 0, 60)


def test_contact_crop_shapes_and_scale() -> None:
    seq = moving_blob(4, 0)
    depth = np.zeros(seq.shape[:3], np.float32)
    x, scale = contact_crop({"rgb": seq, "depth": depth}, 40, 20, "rgbd")
    assert x.shape == (4, 4, 20, 20) and x.dtype == np.float32 and scale == (0.5, 0.5)
    assert x[:, :3].min() >= 0.0 and x[:, :3].max() <= 1.0
    d, _ = contact_crop({"rgb": seq, "depth": depth}, 40, 20, "depth")
    assert d.shape == (4, 1, 20, 20)


def _direction(x: torch.Tensor) -> int:
    """Direction class of the motion of a (T, C, S, S) sequence by phase correlation."""
    import cv2

    a = x[0].mean(0).numpy().astype(np.float32)
    b = x[-1].mean(0).numpy().astype(np.float32)
    (dx, dy), _ = cv2.phaseCorrelate(a, b)
    return angle_to_class(math.degrees(math.atan2(-dy, dx)) % 360)


@pytest.mark.parametrize(("dx", "dy_rows"), [(6, 0), (5, -5), (0, 6), (-4, 4)])
def test_dihedral_labels_follow_the_frames(dx: float, dy_rows: float) -> None:
    seq = moving_blob(dx, dy_rows, h=64, w=64, at=(32, 32))
    x = torch.from_numpy(seq.transpose(0, 3, 1, 2).astype(np.float32) / 255)
    label = _direction(x)
    batch = x[None].repeat(16, 1, 1, 1, 1)
    out, d = dihedral_augment(batch, torch.full((16,), label), torch.Generator().manual_seed(1))
    assert len(set(d.tolist())) > 3  # several symmetries drawn
    for xi, di in zip(out, d, strict=True):
        assert _direction(xi) == int(di)
    _, none = dihedral_augment(batch, torch.full((16,), -1), torch.Generator().manual_seed(1))
    assert (none == -1).all()
    with pytest.raises(ValueError, match="square"):
        dihedral_augment(torch.zeros(1, 2, 3, 4, 5), torch.zeros(1), torch.Generator())
