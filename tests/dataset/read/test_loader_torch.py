"""View.to_torch: tensors, resizing, frames, transforms, targets, and DataLoader workers."""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest

import vtsbench
from vtsbench.dataset.read.loader import VtsDataset
from vtsbench.errors import VtsError

torch = pytest.importorskip("torch")
from torch.utils.data import DataLoader  # noqa: E402

from vtsbench.dataset.read.torch_dataset import frame_numbers  # noqa: E402


@pytest.fixture(scope="module")
def ds(vts_dataset: Path) -> VtsDataset:
    return vtsbench.load(vts_dataset)


def test_static_rgb_depth_rgbd(ds: VtsDataset) -> None:
    view = ds.static
    s = view[0]
    h, w = ds.info.resolution
    x, t = view.to_torch("rgb")[0]
    assert x.shape == (3, h, w) and x.dtype == torch.float32
    assert float(x.min()) >= 0.0 and float(x.max()) <= 1.0
    np.testing.assert_allclose(x.numpy(), s["rgb"].transpose(2, 0, 1) / 255.0, rtol=1e-6)
    d, _ = view.to_torch("depth")[0]
    assert d.shape == (1, h, w)
    np.testing.assert_array_equal(d[0].numpy(), s["depth"])
    rgbd, _ = view.to_torch("rgbd")[0]
    assert rgbd.shape == (4, h, w)
    torch.testing.assert_close(rgbd[:3], x)
    torch.testing.assert_close(rgbd[3:], d)
    assert t == {"sample_id": s["sample_id"], "class_idx": s["class_idx"],
                 "press_depth_mm": pytest.approx(s["press_depth_mm"], nan_ok=True)}


def test_slip_frames_size_transform(ds: VtsDataset) -> None:
    view = ds.slip
    s = view[0]
    t_all = ds.info.frames_per_sequence
    seen = []

    def transform(x: torch.Tensor) -> torch.Tensor:
        seen.append(tuple(x.shape))
        return x * 2

    tv = view.to_torch("rgbd", size=(24, 32), frames=3, transform=transform)
    x, target = tv[0]
    assert x.shape == (3, 4, 24, 32) and seen == [(3, 4, 24, 32)]  # transform after resizing
    picks = frame_numbers(t_all, 3)
    assert picks[0] == 0 and picks[-1] == t_all - 1
    plain, _ = view.to_torch("rgb", frames=3)[0]
    np.testing.assert_allclose(plain.numpy(),
                               s["rgb"][picks].transpose(0, 3, 1, 2) / 255.0, rtol=1e-6)
    assert target["state_idx"] == s["state_idx"]
    assert target["direction"] == (-1 if s["direction"] is None else s["direction"])
    assert target["motion_mm"].shape == (2,)
    assert frame_numbers(t_all, 1).tolist() == [t_all - 1]


def test_resize_is_bilinear_of_the_frame(ds: VtsDataset) -> None:
    s = ds.static[0]
    h, w = ds.info.resolution
    x, _ = ds.static.to_torch("depth", size=(h // 2, w // 2))[0]
    ref = torch.nn.functional.interpolate(torch.from_numpy(s["depth"])[None, None],
                                          size=(h // 2, w // 2), mode="bilinear",
                                          align_corners=False, antialias=True)[0]
    torch.testing.assert_close(x, ref)


def test_rgb_resize_within_one_level_of_float(ds: VtsDataset) -> None:
    s = ds.slip[0]
    h, w = ds.info.resolution
    x, _ = ds.slip.to_torch("rgb", size=(h // 2, w // 3))[0]
    rgb = torch.from_numpy(s["rgb"]).movedim(-1, -3).float() / 255
    ref = torch.nn.functional.interpolate(rgb, size=(h // 2, w // 3), mode="bilinear",
                                          align_corners=False, antialias=True)
    assert x.shape == ref.shape
    assert float((x - ref).abs().max()) <= 1.01 / 255


def test_target_arrays(ds: VtsDataset) -> None:
    s = ds.slip[0]
    _, t = ds.slip.to_torch("rgb", targets=("depth", "contact"))[0]
    np.testing.assert_array_equal(t["depth"].numpy(), s["depth"])
    np.testing.assert_array_equal(t["contact"].numpy(), s["contact"])
    _, t = ds.slip.to_torch("rgb", size=(20, 30), frames=2, targets=("contact",))[0]
    assert t["contact"].shape == (2, 20, 30) and t["contact"].dtype == torch.bool


def test_errors(ds: VtsDataset) -> None:
    for call, match in [
        (lambda: ds.static.to_torch("thermal"), "unsupported modality 'thermal'"),
        (lambda: ds.static.to_torch("rgb", frames=2), "slip sequences only"),
        (lambda: ds.slip.to_torch("rgb", frames=99), "frames must be in 1.."),
        (lambda: ds.slip.to_torch("rgb", size=(0, 4)), "size must be positive"),
        (lambda: ds.slip.to_torch("rgb", targets=("labels",)), "unknown target array"),
    ]:
        with pytest.raises(VtsError, match=match) as e:
            call()
        assert "\n" not in str(e.value)


def _collect(loader: DataLoader) -> tuple[list[str], torch.Tensor]:
    ids: list[str] = []
    xs = []
    for x, t in loader:
        ids += list(t["sample_id"])
        xs.append(x)
    return ids, torch.cat(xs)


@pytest.mark.parametrize("context", ["fork", "spawn"])
def test_dataloader_with_two_workers(ds: VtsDataset, context: str) -> None:
    name = next(n for n in ds.splits if ds.split_file(n).kind == "slip")
    part = max(ds.parts(name), key=lambda p: len(ds.split(name, p)))
    view = ds.split(name, part)
    tv = view.to_torch("rgbd", size=(24, 32), frames=2)
    tv[0]  # arrays opened here must not travel to the workers
    want_ids, want = _collect(DataLoader(tv, batch_size=2, num_workers=0))
    loader = DataLoader(tv, batch_size=2, num_workers=2, multiprocessing_context=context,
                        timeout=120)
    ids, got = _collect(loader)
    assert ids == want_ids == view.ids
    torch.testing.assert_close(got, want)


def test_torch_view_pickles_small(ds: VtsDataset) -> None:
    tv = ds.static.to_torch("rgb")
    tv[0]
    back = pickle.loads(pickle.dumps(tv))
    torch.testing.assert_close(back[0][0], tv[0][0])


def test_joint_transforms_keep_rgb_depth_contact_aligned(vts_dataset: Path) -> None:
    """A flip through `transforms` moves the input and the spatial targets together."""
    from torchvision.transforms import v2

    from vtsbench.dataset.read.torch_dataset import HorizontalFlip
    from vtsbench.labels import MIRROR_X

    ds = vtsbench.load(vts_dataset)
    flips = (("slip", v2.RandomHorizontalFlip(p=1.0)), ("static", v2.RandomVerticalFlip(p=1.0)))
    for kind, flip in flips:
        axis = -1 if isinstance(flip, v2.RandomHorizontalFlip) else -2
        data = ds.view(kind).to_torch("rgbd", targets=("depth", "contact"), transforms=flip)
        x, t = data[1]
        s = ds.view(kind)[1]
        assert type(x) is torch.Tensor and type(t["depth"]) is torch.Tensor
        rgb = np.flip(s["rgb"], axis - 1)
        np.testing.assert_allclose(x[..., :3, :, :].numpy() * 255,
                                   np.moveaxis(rgb, -1, -3), atol=1e-3)
        np.testing.assert_array_equal(x[..., 3, :, :].numpy(), np.flip(s["depth"], axis))
        np.testing.assert_array_equal(t["depth"].numpy(), np.flip(s["depth"], axis))
        np.testing.assert_array_equal(t["contact"].numpy(), np.flip(s["contact"], axis))
        assert t["contact"].any()  # a flip of an empty mask would prove nothing
    # the project's own flip also mirrors the slip labels
    slip = ds.slip.where(state="slip")
    data = slip.to_torch("rgb", targets=("contact",), transforms=HorizontalFlip(p=1.0))
    x, t = data[0]
    s = slip[0]
    assert t["direction"] == MIRROR_X[s["direction"]]
    assert t["motion_mm"][0] == -np.float32(s["motion_mm"][0])
    np.testing.assert_array_equal(t["contact"].numpy(), np.flip(s["contact"], -1))


def test_target_transform_classes_and_plot(vts_dataset: Path) -> None:
    ds = vtsbench.load(vts_dataset)
    data = ds.slip.to_torch("rgb", frames=2, targets=("depth", "contact"),
                            target_transform=lambda t: t["state_idx"])
    x, y = data[0]
    assert y == ds.slip[0]["state_idx"] and tuple(x.shape[:2]) == (2, 3)
    assert data.classes == ["static", "press", "slip"]
    assert ds.static.to_torch().classes == ds.info.objects
    assert data.class_names["direction"][2] == "up"
    full = ds.slip.to_torch("rgb", targets=("depth", "contact"))
    fig = full.plot(full[0])
    assert len(fig.axes) == 4  # rgb, depth, its colour bar, contact
    assert ds.slip[0]["sample_id"] in fig.texts[0].get_text()
    fig = ds.static.plot(ds.static[0])
    assert len(fig.axes) == 4 and ds.static[0]["object"] in fig.texts[0].get_text()
    depth_only = ds.static.to_torch("depth")
    assert len(depth_only.plot(depth_only[0]).axes) == 2
