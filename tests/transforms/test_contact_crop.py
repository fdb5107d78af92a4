"""Contact crops and the quarter-turn augmentation: the crop follows the moving imprint, and a
turned or mirrored sequence moves in the direction its mapped label says."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from vtsbench.labels import angle_to_class
from vtsbench.transforms.contact_crop import contact_crop, crop_box, crop_center
from vtsbench.transforms.symmetry import dihedral_augment, dihedral_average


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


@pytest.mark.parametrize(("dx", "dy_rows"), [(6, 0), (5, -5), (-4, 4)])
def test_dihedral_average_maps_every_view_back(dx: float, dy_rows: float) -> None:
    """Test-time averaging: a 'model' that reads each turned view's motion right gives one-hot
    probabilities on the unturned sequence's bin after the mapping back; a model that answers
    one fixed bin whatever it sees is spread over that bin's orbit (bin 0: the 4 even bins,
    each reached by two of the 8 symmetries)."""
    seq = moving_blob(dx, dy_rows, h=64, w=64, at=(32, 32))
    x = torch.from_numpy(seq.transpose(0, 3, 1, 2).astype(np.float32) / 255)
    label = _direction(x)

    def reader(batch: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        d = torch.tensor([_direction(v) for v in batch])
        return torch.zeros(len(batch), 3), torch.nn.functional.one_hot(d, 8).float() * 50

    ps, pd = dihedral_average(reader, x)
    assert int(pd.argmax()) == label and float(pd.max()) > 0.99
    assert torch.allclose(ps, torch.full((3,), 1 / 3)) and torch.isclose(pd.sum(), torch.ones(()))

    def fixed(batch: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return torch.zeros(len(batch), 3), torch.nn.functional.one_hot(
            torch.zeros(len(batch), dtype=torch.long), 8).float() * 50

    _, spread = dihedral_average(fixed, x)
    assert torch.allclose(spread, torch.tensor([0.25, 0.0] * 4), atol=1e-3)


def test_crop_flow_follows_the_motion() -> None:
    import cv2

    from vtsbench.transforms.contact_crop import FLOW_SOFT_PX, crop_flow

    seq = moving_blob(6, -3, h=64, w=64, at=(30, 34))
    grey = np.stack([cv2.cvtColor(f, cv2.COLOR_RGB2GRAY) for f in seq])
    f = crop_flow(grey, 32)
    assert f.shape == (4, 2, 32, 32) and not f[0].any()
    # 6 px right and 3 px up the rows over the sequence: the strongest flow points that way
    # (26.6 degrees, class 1) and is at most 3 px long at half size
    mag = np.hypot(f[-1, 0], f[-1, 1])
    fx, fy = f[-1, 0][mag > 0.5 * mag.max()].mean(), f[-1, 1][mag > 0.5 * mag.max()].mean()
    assert angle_to_class(math.degrees(math.atan2(-fy, fx)) % 360) == 1
    px = FLOW_SOFT_PX * np.arctanh(min(float(mag.max()), 0.999999))  # back to pixels
    assert 0.5 < px < 4.0 and mag.max() < 1.0
    x, _ = contact_crop({"rgb": seq}, 40, 20, "rgb", flow="dis")
    assert x.shape == (4, 5, 20, 20)
    with pytest.raises(ValueError, match="flow must be"):
        contact_crop({"rgb": seq}, 40, 20, "rgb", flow="tvl1")


def test_pretrained_filters_of_extra_channels_start_at_zero() -> None:
    from vtsbench.models.timesformer import adapt_patch_weight

    w = torch.randn(4, 3, 2, 2)
    a = adapt_patch_weight(w, 8, extra=2)
    assert a.shape == (4, 8, 2, 2)
    assert torch.equal(a[:, :3], w) and not a[:, 3:].any()
    d = adapt_patch_weight(w, 3, extra=2)
    assert torch.allclose(d[:, :1], w.mean(1, keepdim=True)) and not d[:, 1:].any()


def test_dihedral_turns_flow_vectors_with_the_frames() -> None:
    import cv2

    from vtsbench.transforms.contact_crop import crop_flow

    def flow_dir(frames: torch.Tensor) -> int:
        grey = (frames.mean(1).numpy() * 255).astype(np.uint8)
        f = crop_flow(grey, grey.shape[-1])[-1]
        return _vec_dir(torch.from_numpy(f))

    def _vec_dir(f: torch.Tensor) -> int:
        mag = torch.hypot(f[0], f[1])
        sel = mag > 0.5 * mag.max()
        fx, fy = float(f[0][sel].mean()), float(f[1][sel].mean())
        return angle_to_class(math.degrees(math.atan2(-fy, fx)) % 360)

    seq = moving_blob(4, -4, h=48, w=48, at=(24, 24))  # 45 degrees: a bin centre
    frames = torch.from_numpy(seq.transpose(0, 3, 1, 2).astype(np.float32) / 255)
    grey = np.stack([cv2.cvtColor(f, cv2.COLOR_RGB2GRAY) for f in seq])
    x = torch.cat([frames, torch.from_numpy(crop_flow(grey, 48))], dim=1)
    label = _vec_dir(x[-1, 3:])
    assert label == flow_dir(frames)
    out, d = dihedral_augment(x[None].repeat(12, 1, 1, 1, 1), torch.full((12,), label),
                              torch.Generator().manual_seed(3), vector=(3, 4))
    assert len(set(d.tolist())) > 3
    for xi, di in zip(out, d, strict=True):
        assert _vec_dir(xi[-1, 3:]) == int(di) == flow_dir(xi[:, :3])


def moving_bar(dx: float, dy_rows: float, t: int = 5, h: int = 96, w: int = 128) -> np.ndarray:
    """(T, H, W, 3) uint8: a long textured bar (an elongated imprint) moving by (dx, dy_rows)."""
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    out = []
    for k in range(t):
        cx, cy = w / 2 - 4 + dx * k / (t - 1), h / 2 + dy_rows * k / (t - 1)
        inside = (np.abs(xs - cx) < 40) & (np.abs(ys - cy) < 6)
        tex = 0.5 + 0.5 * np.sin(0.8 * (xs - cx) + 0.3 * (ys - cy))
        img = np.where(inside, 70 + 140 * tex, 40)
        out.append(np.repeat(img[..., None], 3, axis=2).astype(np.uint8))
    return np.stack(out)


@pytest.mark.parametrize("dx,dy", [(8.0, 0.0), (-6.0, 6.0), (0.0, -7.0), (3.0, 0.0)])
def test_shift_field_holds_the_displacement_where_the_gel_moves(dx: float, dy: float) -> None:
    import cv2

    from vtsbench.transforms.motion import shift_field

    seq = moving_bar(dx, dy)
    grey = np.stack([cv2.cvtColor(f, cv2.COLOR_RGB2GRAY) for f in seq])
    f = shift_field(grey)
    assert f.shape == (5, 2, 96, 128) and f.dtype == np.float32 and not f[0].any()
    peak = np.unravel_index(np.hypot(f[-1, 0], f[-1, 1]).argmax(), f.shape[2:])
    assert f[-1, 0][peak] == pytest.approx(dx, abs=0.5)
    assert f[-1, 1][peak] == pytest.approx(dy, abs=0.5)
    assert not f[-1, :, 0, 0].any() and not f[-1, :, -1, -1].any()  # still corners stay 0
    # each frame's field grows with its share of the motion
    lengths = [float(np.hypot(*f[t, :, peak[0], peak[1]])) for t in range(5)]
    assert lengths == sorted(lengths)


def test_shift_field_is_zero_without_motion_and_for_one_frame() -> None:
    from vtsbench.transforms.motion import shift_field

    still = np.full((4, 32, 32), 90, np.uint8)
    assert not shift_field(still).any()
    assert not shift_field(still[:1]).any()


def test_shift_channels_follow_the_motion_of_an_elongated_imprint() -> None:
    # sliding along its own length: the dense flow sees little of it (aperture), the shift
    # channels the whole displacement, in pixels at the model's input, compressed
    from vtsbench.transforms.contact_crop import FLOW_SOFT_PX

    seq = moving_bar(10.0, 0.0, h=160, w=200)
    x, (sx, _) = contact_crop({"rgb": seq}, 96, 48, "rgb", flow="shift")
    assert x.shape == (5, 5, 48, 48)
    f = x[-1, 3:]
    mag = np.hypot(f[0], f[1])
    fx, fy = f[0][mag > 0.5 * mag.max()].mean(), f[1][mag > 0.5 * mag.max()].mean()
    assert angle_to_class(math.degrees(math.atan2(-fy, fx)) % 360) == 0
    px = FLOW_SOFT_PX * np.arctanh(min(float(mag.max()), 0.999999))
    assert px == pytest.approx(10.0 * sx, abs=0.5)


def test_flow_mask_keeps_the_flow_only_where_the_gel_is_in_contact() -> None:
    """`flow_mask`: the dis channels are zero outside the union of the contact masks and the same
    as without the mask inside it; no contact masks keep everything."""
    from vtsbench.transforms.contact_crop import contact_mask

    seq = moving_blob(4, 0)
    contact = np.zeros(seq.shape[:3], bool)
    contact[:, 15:35, 40:65] = True
    s = {"rgb": seq, "contact": contact}
    free, _ = contact_crop(s, 40, 40, "rgb", flow="dis")
    masked, _ = contact_crop(s, 40, 40, "rgb", flow="dis", flow_mask=True)
    box = crop_box(crop_center(seq, contact), 40, seq.shape[1:3])
    m = contact_mask(s, box, 40).astype(bool)
    assert 0 < m.sum() < m.size
    assert np.array_equal(masked[:, :3], free[:, :3])
    assert np.all(masked[:, 3:][:, :, ~m] == 0.0)
    assert np.allclose(masked[:, 3:][:, :, m], free[:, 3:][:, :, m])
    assert contact_mask({"rgb": seq}, box, 40).min() == 1.0
