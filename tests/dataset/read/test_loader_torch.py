"""View.to_torch: uint8 frames resized with OpenCV (and the float32 tensors of dtype="float32"),
frames, transforms, targets, batched reads, and DataLoader workers."""

from __future__ import annotations

import pickle
from pathlib import Path

import cv2
import numpy as np
import pytest

import vtsbench
from vtsbench.dataset.read.loader import VtsDataset
from vtsbench.errors import VtsError

torch = pytest.importorskip("torch")
from torch.utils.data import DataLoader  # noqa: E402

from vtsbench.dataset.read.torch_dataset import as_float, frame_numbers  # noqa: E402


@pytest.fixture(scope="module")
def ds(vts_dataset: Path) -> VtsDataset:
    return vtsbench.load(vts_dataset)


def _area(frames: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """The reference resize: cv2.resize INTER_AREA of each stored frame."""
    return np.stack([cv2.resize(f, size[::-1], interpolation=cv2.INTER_AREA) for f in frames])


def test_uint8_frames_by_default(ds: VtsDataset) -> None:
    h, w = ds.info.resolution
    for kind, lead in (("static", ()), ("slip", (ds.info.frames_per_sequence,))):
        view = ds.view(kind)
        s = view[1]
        x, t = view.to_torch("rgb")[1]
        assert x.dtype == torch.uint8 and tuple(x.shape) == (*lead, 3, h, w) and x.is_contiguous()
        np.testing.assert_array_equal(x.numpy(), np.moveaxis(s["rgb"], -1, -3))
        d, _ = view.to_torch("depth")[1]
        assert d.dtype == torch.float32 and tuple(d.shape) == (*lead, 1, h, w)
        np.testing.assert_array_equal(d[..., 0, :, :].numpy(), s["depth"])
        rgbd, _ = view.to_torch("rgbd")[1]  # the two, no float copy of the frames
        assert set(rgbd) == {"rgb", "depth"}
        torch.testing.assert_close(rgbd["rgb"], x, rtol=0, atol=0)
        torch.testing.assert_close(rgbd["depth"], d, rtol=0, atol=0)
        assert t["sample_id"] == s["sample_id"] and t["class_idx"] == s["class_idx"]


def test_uint8_resize_is_cv2_inter_area_of_the_stored_frame(ds: VtsDataset) -> None:
    view = ds.slip
    s = view[2]
    for size in ((24, 32), (50, 70), (96, 40)):
        x, t = view.to_torch("rgbd", size=size, targets=("depth", "contact"))[2]
        assert x["rgb"].dtype == torch.uint8 and tuple(x["rgb"].shape[-3:]) == (3, *size)
        np.testing.assert_array_equal(np.moveaxis(x["rgb"].numpy(), -3, -1),
                                      _area(s["rgb"], size))
        np.testing.assert_array_equal(x["depth"][:, 0].numpy(), _area(s["depth"], size))
        np.testing.assert_array_equal(t["depth"].numpy(), _area(s["depth"], size))
        assert t["contact"].dtype == torch.bool and tuple(t["contact"].shape[-2:]) == size
        ref = np.stack([cv2.resize(f.view(np.uint8), size[::-1],
                                   interpolation=cv2.INTER_NEAREST) for f in s["contact"]])
        np.testing.assert_array_equal(t["contact"].numpy(), ref.astype(bool))
        assert t["depth"].data_ptr() != x["depth"].data_ptr()  # not one tensor twice


def test_frames_and_transform(ds: VtsDataset) -> None:
    view = ds.slip
    s = view[0]
    t_all = ds.info.frames_per_sequence
    seen = []

    def transform(x: torch.Tensor) -> torch.Tensor:
        seen.append(tuple(x.shape))
        return x

    tv = view.to_torch("rgb", size=(24, 32), frames=3, transform=transform)
    x, target = tv[0]
    assert x.shape == (3, 3, 24, 32) and seen == [(3, 3, 24, 32)]  # transform after resizing
    picks = frame_numbers(t_all, 3)
    assert picks[0] == 0 and picks[-1] == t_all - 1
    plain, _ = view.to_torch("rgb", frames=3)[0]
    np.testing.assert_array_equal(plain.numpy(), s["rgb"][picks].transpose(0, 3, 1, 2))
    assert target["state_idx"] == s["state_idx"]
    assert target["direction"] == (-1 if s["direction"] is None else s["direction"])
    assert target["motion_mm"].shape == (2,)
    assert frame_numbers(t_all, 1).tolist() == [t_all - 1]


def test_getitems_equals_one_by_one(ds: VtsDataset) -> None:
    """A batch read (shuffled, with a repeat) gives exactly the items read one by one."""
    for dtype in ("uint8", "float32"):
        tv = ds.slip.to_torch("rgbd", size=(20, 30), frames=2, targets=("depth", "contact"),
                              dtype=dtype)
        items = [5, 0, 3, 4, 0, 8]
        batch = tv.__getitems__(items)
        for i, (x, t) in zip(items, batch, strict=True):
            x1, t1 = tv[i]
            if isinstance(x, dict):
                assert all(torch.equal(x[k], x1[k]) for k in x1)
            else:
                assert torch.equal(x, x1)
            assert t["sample_id"] == t1["sample_id"] == ds.slip.ids[i]
            assert torch.equal(t["depth"], t1["depth"]) and torch.equal(t["contact"],
                                                                        t1["contact"])


def test_float32_keeps_the_earlier_tensors(ds: VtsDataset) -> None:
    """dtype="float32": rgb in [0, 1], bilinear antialiased resize, rgbd as 4 channels; as_float
    of the uint8 item gives the same values at the stored size."""
    view = ds.static
    s = view[0]
    h, w = ds.info.resolution
    x, t = view.to_torch("rgb", dtype="float32")[0]
    assert x.shape == (3, h, w) and x.dtype == torch.float32
    assert float(x.min()) >= 0.0 and float(x.max()) <= 1.0
    np.testing.assert_allclose(x.numpy(), s["rgb"].transpose(2, 0, 1) / 255.0, rtol=1e-6)
    d, _ = view.to_torch("depth", dtype="float32")[0]
    np.testing.assert_array_equal(d[0].numpy(), s["depth"])
    rgbd, _ = view.to_torch("rgbd", dtype="float32")[0]
    assert rgbd.shape == (4, h, w)
    torch.testing.assert_close(rgbd[:3], x)
    torch.testing.assert_close(rgbd[3:], d)
    u8, _ = view.to_torch("rgbd")[0]
    torch.testing.assert_close(as_float(u8), rgbd)
    assert t == {"sample_id": s["sample_id"], "class_idx": s["class_idx"],
                 "press_depth_mm": pytest.approx(s["press_depth_mm"], nan_ok=True)}
    x, _ = view.to_torch("depth", size=(h // 2, w // 2), dtype="float32")[0]
    ref = torch.nn.functional.interpolate(torch.from_numpy(s["depth"])[None, None],
                                          size=(h // 2, w // 2), mode="bilinear",
                                          align_corners=False, antialias=True)[0]
    torch.testing.assert_close(x, ref)
    slip = ds.slip[0]
    x, _ = ds.slip.to_torch("rgb", size=(h // 2, w // 3), dtype="float32")[0]
    rgb = torch.from_numpy(slip["rgb"]).movedim(-1, -3).float() / 255
    ref = torch.nn.functional.interpolate(rgb, size=(h // 2, w // 3), mode="bilinear",
                                          align_corners=False, antialias=True)
    assert x.shape == ref.shape
    assert float((x - ref).abs().max()) <= 1.01 / 255


def test_target_arrays(ds: VtsDataset) -> None:
    s = ds.slip[0]
    _, t = ds.slip.to_torch("rgb", targets=("depth", "contact"))[0]
    np.testing.assert_array_equal(t["depth"].numpy(), s["depth"])
    np.testing.assert_array_equal(t["contact"].numpy(), s["contact"])
    for dtype in ("uint8", "float32"):
        _, t = ds.slip.to_torch("rgb", size=(20, 30), frames=2, targets=("contact",),
                                dtype=dtype)[0]
        assert t["contact"].shape == (2, 20, 30) and t["contact"].dtype == torch.bool


def test_errors(ds: VtsDataset) -> None:
    for call, match in [
        (lambda: ds.static.to_torch("thermal"), "unsupported modality 'thermal'"),
        (lambda: ds.static.to_torch("rgb", frames=2), "slip sequences only"),
        (lambda: ds.slip.to_torch("rgb", frames=99), "frames must be in 1.."),
        (lambda: ds.slip.to_torch("rgb", size=(0, 4)), "size must be positive"),
        (lambda: ds.slip.to_torch("rgb", targets=("labels",)), "unknown target array"),
        (lambda: ds.slip.to_torch("rgb", dtype="float16"), "unsupported dtype 'float16'"),
    ]:
        with pytest.raises(VtsError, match=match) as e:
            call()
        assert "\n" not in str(e.value)


def _collect(loader: DataLoader) -> tuple[list[str], list]:
    ids: list[str] = []
    xs = []
    for x, t in loader:
        ids += list(t["sample_id"])
        xs.append(x)
    return ids, xs


@pytest.mark.parametrize("context", ["fork", "spawn"])
def test_dataloader_with_two_workers(ds: VtsDataset, context: str) -> None:
    """Workers open the store themselves (nothing open is pickled) and give the very batches
    of 0 workers: uint8 rgb and mm depth of rgbd, resized in the worker."""
    name = next(n for n in ds.splits if ds.split_file(n).kind == "slip")
    part = max(ds.parts(name), key=lambda p: len(ds.split(name, p)))
    view = ds.split(name, part)
    tv = view.to_torch("rgbd", size=(24, 32), frames=2, targets=("contact",))
    tv[0]  # arrays opened here must not travel to the workers
    want_ids, want = _collect(DataLoader(tv, batch_size=2, num_workers=0))
    loader = DataLoader(tv, batch_size=2, num_workers=2, multiprocessing_context=context,
                        timeout=120)
    ids, got = _collect(loader)
    assert ids == want_ids == view.ids
    assert len(got) == len(want)
    for a, b in zip(got, want, strict=True):
        assert a["rgb"].dtype == torch.uint8 and a["rgb"].shape[1:] == (2, 3, 24, 32)
        assert torch.equal(a["rgb"], b["rgb"]) and torch.equal(a["depth"], b["depth"])


def test_torch_view_pickles_small(ds: VtsDataset) -> None:
    tv = ds.static.to_torch("rgb")
    tv[0]
    data = pickle.dumps(tv)
    assert len(data) < 2**20  # the index, no open array and no pixels
    back = pickle.loads(data)
    assert torch.equal(back[0][0], tv[0][0])


def test_joint_transforms_keep_rgb_depth_contact_aligned(vts_dataset: Path) -> None:
    """A flip through `transforms` moves the input and the spatial targets together."""
    from torchvision.transforms import v2

    from vtsbench.dataset.read.torch_dataset import HorizontalFlip
    from vtsbench.labels import MIRROR_X

    ds = vtsbench.load(vts_dataset)
    flips = (("slip", v2.RandomHorizontalFlip(p=1.0)), ("static", v2.RandomVerticalFlip(p=1.0)))
    for kind, flip in flips:
        axis = -1 if isinstance(flip, v2.RandomHorizontalFlip) else -2
        s = ds.view(kind)[1]
        rgb = np.moveaxis(np.flip(s["rgb"], axis - 1), -1, -3)
        data = ds.view(kind).to_torch("rgbd", targets=("depth", "contact"), transforms=flip,
                                      dtype="float32")
        x, t = data[1]
        assert type(x) is torch.Tensor and type(t["depth"]) is torch.Tensor
        np.testing.assert_allclose(x[..., :3, :, :].numpy() * 255, rgb, atol=1e-3)
        np.testing.assert_array_equal(x[..., 3, :, :].numpy(), np.flip(s["depth"], axis))
        np.testing.assert_array_equal(t["depth"].numpy(), np.flip(s["depth"], axis))
        np.testing.assert_array_equal(t["contact"].numpy(), np.flip(s["contact"], axis))
        assert t["contact"].any()  # a flip of an empty mask would prove nothing
        data = ds.view(kind).to_torch("rgbd", targets=("contact",), transforms=flip)
        x, t = data[1]  # uint8: each tensor of the rgbd dict moves
        assert type(x["rgb"]) is torch.Tensor and x["rgb"].dtype == torch.uint8
        np.testing.assert_array_equal(x["rgb"].numpy(), rgb)
        np.testing.assert_array_equal(x["depth"][..., 0, :, :].numpy(),
                                      np.flip(s["depth"], axis))
        np.testing.assert_array_equal(t["contact"].numpy(), np.flip(s["contact"], axis))
    # the project's own flip also mirrors the slip labels
    slip = ds.slip.where(state="slip")
    data = slip.to_torch("rgbd", targets=("contact",), transforms=HorizontalFlip(p=1.0))
    x, t = data[0]
    s = slip[0]
    assert t["direction"] == MIRROR_X[s["direction"]]
    assert t["motion_mm"][0] == -np.float32(s["motion_mm"][0])
    np.testing.assert_array_equal(t["contact"].numpy(), np.flip(s["contact"], -1))
    np.testing.assert_array_equal(x["depth"][:, 0].numpy(), np.flip(s["depth"], -1))


def test_target_transform_classes_and_plot(vts_dataset: Path) -> None:
    ds = vtsbench.load(vts_dataset)
    data = ds.slip.to_torch("rgb", frames=2, targets=("depth", "contact"),
                            target_transform=lambda t: t["state_idx"])
    x, y = data[0]
    assert y == ds.slip[0]["state_idx"] and tuple(x.shape[:2]) == (2, 3)
    assert data.classes == ["static", "press", "slip"]
    assert ds.static.to_torch().classes == ds.info.objects
    assert data.class_names["direction"][2] == "up"
    for dtype in ("uint8", "float32"):
        full = ds.slip.to_torch("rgb", targets=("depth", "contact"), dtype=dtype)
        fig = full.plot(full[0])
        assert len(fig.axes) == 4  # rgb, depth, its colour bar, contact
        assert ds.slip[0]["sample_id"] in fig.texts[0].get_text()
        rgbd = ds.slip.to_torch("rgbd", dtype=dtype)
        assert len(rgbd.plot(rgbd[0]).axes) == 3  # rgb, depth, its colour bar
    fig = ds.static.plot(ds.static[0])
    assert len(fig.axes) == 4 and ds.static[0]["object"] in fig.texts[0].get_text()
    depth_only = ds.static.to_torch("depth")
    assert len(depth_only.plot(depth_only[0]).axes) == 2
