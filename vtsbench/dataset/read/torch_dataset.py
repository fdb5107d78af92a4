"""`View.to_torch`: a torch Dataset of (tensor, target dict) over a view, for DataLoader workers.

Frames come as uint8, resized in the worker with OpenCV (INTER_AREA) before any conversion, so
a worker moves a quarter of the bytes of float32 rgb through the DataLoader's shared memory and
makes no float copy; the model converts (`as_float`, or `x.float().div_(255)`), on its device.
`dtype="float32"` gives the float tensors of earlier versions bit for bit (rgb in [0, 1], torch's
antialiased bilinear resize). A batch (DataLoader's `__getitems__`) reads its rows in row order,
one store read per run of consecutive rows, and writes each frame once into the batch's tensors,
which default_collate hands on without stacking again (`torch_batch`). The Zarr arrays are
opened lazily in each worker process, never pickled. This module imports torch: import it only
where torch is wanted.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
import torch.nn.functional as F
from torch.utils.data import Dataset

from ...errors import VtsError
from ...labels import DIRECTION_NAMES, MIRROR_X, STATES
from .torch_batch import batch_of, batch_tensors, in_worker, item_at, put_frames
from .torch_loader import Loadable

if TYPE_CHECKING:
    from .episodes import Windows
    from .view import View

MODALITIES = ("rgb", "depth", "rgbd")
TARGET_ARRAYS = ("depth", "contact")
#: Output types: uint8 frames (the default) or the float32 tensors of earlier versions.
DTYPES = ("uint8", "float32")


def frame_numbers(t: int, k: int) -> np.ndarray:
    """k evenly spaced frames of a T-frame sequence, first and last included; k = 1 gives the
    last frame (the one press depth and contact centre describe)."""
    if not 1 <= k <= t:
        raise VtsError(f"frames must be in 1..{t} (frames per sequence), got {k}")
    if k == 1:
        return np.array([t - 1])
    return np.linspace(0, t - 1, k).round().astype(np.int64)


def _check_choices(modality: str, dtype: str, targets: Sequence[str]) -> None:
    """The modality, dtype and target arrays a torch view is asked for, each one of its set."""
    if modality not in MODALITIES:
        raise VtsError(f"unsupported modality {modality!r}; use one of {', '.join(MODALITIES)}")
    if dtype not in DTYPES:
        raise VtsError(f"unsupported dtype {dtype!r}; use {' or '.join(DTYPES)}")
    bad = [t for t in targets if t not in TARGET_ARRAYS]
    if bad:
        raise VtsError(f"unknown target array {bad[0]!r}; use {', '.join(TARGET_ARRAYS)}")


def _check_size(size: Any) -> tuple[int, int] | None:
    if size is None:
        return None
    try:
        h, w = (int(v) for v in size)
    except (TypeError, ValueError):
        raise VtsError(f"size must be (height, width), got {size!r}") from None
    if h < 1 or w < 1:
        raise VtsError(f"size must be positive, got {size!r}")
    return h, w


def resize(x: torch.Tensor, size: tuple[int, int], mode: str = "bilinear") -> torch.Tensor:
    """Resize (..., C, H, W) to size: bilinear (antialiased) for images, nearest for masks;
    uint8 stays uint8 (rounded). The resize of dtype="float32"."""
    if tuple(x.shape[-2:]) == size:
        return x
    lead = x.shape[:-3]
    flat = x.reshape(-1, *x.shape[-3:])
    if mode == "nearest":
        out = F.interpolate(flat, size=size, mode="nearest")
    else:
        out = F.interpolate(flat, size=size, mode="bilinear", align_corners=False,
                            antialias=True)
    return out.reshape(*lead, *out.shape[-3:])


def as_float(x: Any, device: Any = None) -> torch.Tensor:
    """The float32 input of a uint8 item or batch, on `device`: rgb / 255 in [0, 1], depth in
    mm, rgbd (a dict) as 4 channels (rgb, depth): the model's first step, done where the batch
    arrives (on a GPU it costs nothing next to the copy)."""
    if isinstance(x, dict):
        rgb, depth = as_float(x["rgb"], device), as_float(x["depth"], device)
        return torch.cat([rgb, depth], dim=-3)
    x = x.to(device, non_blocking=True) if device is not None else x
    return x.float().div_(255) if x.dtype == torch.uint8 else x.float()


class TorchView(Loadable, Dataset):
    """(tensor, target) items of a view.

    dtype "uint8" (default): rgb uint8 as C x H x W, depth float32 mm as one channel, rgbd a
    dict {"rgb", "depth"} of the two (no float copy of the frames is made); `size` resizes in
    the worker with OpenCV INTER_AREA before any conversion (masks: nearest). dtype "float32":
    rgb float32 in [0, 1], depth mm, rgbd one 4-channel tensor, resized with torch's antialiased
    bilinear (the tensors of earlier versions, bit for bit). Slip items are T x C x H x W.
    target: sample_id, class_idx, press_depth_mm (NaN when unknown) and for slip state_idx,
    direction (-1 when none) and motion_mm (2,), plus the arrays named in `targets` ("depth"
    in mm, "contact" bool) as (T x) H x W.

    Transforms, as in torchvision and TorchGeo: `transforms` gets the whole sample as one dict
    ({"image": tensor, **target}; with torchvision installed the tensor is a tv_tensors.Image,
    or a Video for a sequence, and the depth and contact targets are tv_tensors.Mask, so a
    torchvision.transforms.v2 transform moves them together) and returns it; then `transform`
    gets the tensor alone and `target_transform` the target.

    `loader(batch_size, shuffle=..., num_workers=...)`: the DataLoader's batches, its workers'
    passed through reused shared memory (`torch_loader`).
    """

    def __init__(self, view: View, modality: str = "rgb", size: Sequence[int] | None = None,
                 frames: int | None = None, transform: Callable[[Any], Any] | None = None,
                 targets: Sequence[str] = (),
                 transforms: Callable[[dict[str, Any]], dict[str, Any]] | None = None,
                 target_transform: Callable[[Any], Any] | None = None,
                 dtype: str = "uint8") -> None:
        _check_choices(modality, dtype, targets)
        if frames is not None and view.kind != "slip":
            raise VtsError("frames apply to slip sequences only")
        self.view, self.modality, self.transform = view, modality, transform
        self.transforms, self.target_transform = transforms, target_transform
        self.size, self.dtype = _check_size(size), dtype
        self.targets = tuple(targets)
        t = view.dataset.info.frames_per_sequence
        self.frames = None if frames is None else frame_numbers(t, int(frames))
        self.inputs = {"rgb": ("rgb",), "depth": ("depth",), "rgbd": ("rgb", "depth")}[modality]
        from .arrays import check_arrays

        check_arrays(view.dataset.info, self.inputs, f"modality {modality!r}")
        for name in self.targets:
            check_arrays(view.dataset.info, (name,), f"target {name!r}")
        self.arrays = tuple(dict.fromkeys(self.inputs + self.targets))

    def __len__(self) -> int:
        return len(self.view)

    def __repr__(self) -> str:
        return (f"TorchView({self.view.kind}, {len(self)} samples, modality={self.modality}, "
                f"size={self.size}, frames={None if self.frames is None else len(self.frames)}, "
                f"dtype={self.dtype})")

    def __getitem__(self, i: int) -> tuple[Any, dict[str, Any]]:
        return tuple(self.__getitems__([i])[0])  # type: ignore[return-value]

    def __getitems__(self, items: Sequence[int]) -> list[tuple[Any, dict[str, Any]]]:
        """Several items read together (DataLoader calls this for a batch): their rows sorted
        and read with one store read per contiguous run, each frame written (resized, channels
        first) into its place in the batch's tensors, of which the items are views; without
        transforms, default_collate hands those tensors on (`collate_batch`)."""
        items = [int(i) for i in items]
        metas = self.view.metas(items)
        if self.dtype == "float32":
            out: list[Any] = [None] * len(items)
            for ks, arrays in self._runs(items):
                for j, k in enumerate(ks):
                    a = {n: v[j] for n, v in arrays.items()}
                    out[k] = self._item(self._float_tensor(a),
                                        self._target(metas[k], self._float_arrays(a)))
            return out
        plain = self.transforms is None and self.transform is None \
            and self.target_transform is None
        shared = plain and in_worker()
        bufs: dict[str, torch.Tensor] = {}
        for ks, arrays in self._runs(items):
            bufs = bufs or batch_tensors(arrays, len(items), self.inputs, self.size, shared)
            for name, a in arrays.items():
                dst = bufs[name].numpy()
                for j, k in enumerate(ks):
                    put_frames(name, a[j], dst[k])
        if not items:
            return []
        whole = batch_of(bufs, self.inputs, self.modality, self.targets, shared)
        out = []
        for k, meta in enumerate(metas):
            x = item_at(whole.x, k)
            target = self._target(meta, {n: t[k] for n, t in whole.spatial.items()})
            out.append(whole.add(x, target) if plain else self._item(x, target))
        return out

    def _runs(self, items: list[int]) -> Iterator[tuple[list[int], dict[str, np.ndarray]]]:
        """The items' arrays, one store read per run of consecutive rows (in row order), as
        (the items' places in `items`, their arrays) per run, read as they are used.

        One read per run rather than one for the whole batch: the loader would copy the runs
        into one batch array (and make its depth in mm at batch size, past the allocator's
        reuse threshold); per run, the arrays are made once. A shuffled batch of 4 slip samples
        at 480x640 measured 15 against 20 ms of CPU a sample (rgbd, one thread).
        """
        if not items:
            return
        rows = self.view.rows[np.asarray(items, np.int64)]
        order = np.argsort(rows, kind="stable")
        cuts = np.flatnonzero(np.diff(rows[order]) != 1) + 1
        for run in np.split(order, cuts):
            ks = [int(k) for k in run]
            yield ks, self.view.read([items[k] for k in ks], self.arrays, frames=self.frames)

    @property
    def classes(self) -> list[str]:
        """Names of the view's main label: the objects (class_idx) for static samples, the
        states (state_idx) for slip samples; `class_names` has every label's."""
        return self.class_names["state_idx" if self.view.kind == "slip" else "class_idx"]

    @property
    def class_names(self) -> dict[str, list[str]]:
        """Names of every label of the target: class_idx (objects), and for slip state_idx and
        direction."""
        names = {"class_idx": list(self.view.dataset.info.objects)}
        if self.view.kind == "slip":
            names["state_idx"] = list(STATES)
            names["direction"] = list(DIRECTION_NAMES)
        return names

    def plot(self, sample: tuple[Any, dict[str, Any]], frame: int = -1) -> Any:
        """A matplotlib Figure of one item (x, target) as this view gives it: its RGB, depth
        and contact (one frame of a sequence, default the last) with its labels."""
        from .plot import labels_text, plot_arrays

        x, target = sample
        x = as_float(x if isinstance(x, dict) else torch.as_tensor(x)).detach().cpu()
        seq = x.ndim == 4
        if seq:
            x = x[frame]

        def pick(a: Any) -> np.ndarray | None:
            if a is None:
                return None
            a = torch.as_tensor(a).detach().cpu()
            return (a[frame] if seq and a.ndim == 3 else a).numpy()

        rgb = depth = None
        if self.modality in ("rgb", "rgbd"):
            rgb = x[:3].permute(1, 2, 0).clamp(0, 1).numpy()
        if self.modality in ("depth", "rgbd"):
            depth = x[-1].numpy()
        if depth is None:
            depth = pick(target.get("depth"))
        title = labels_text(self.view.dataset.info, _int(target.get("class_idx")),
                            _int(target.get("state_idx")), _int(target.get("direction")),
                            target.get("sample_id"))
        return plot_arrays(rgb, depth, pick(target.get("contact")), title)

    def _item(self, x: Any, target: dict[str, Any]) -> tuple[Any, dict[str, Any]]:
        if self.transforms is not None:
            x, target = _unwrap(self.transforms(_wrap(x, target)))
        if self.transform is not None:
            x = self.transform(x)
        if self.target_transform is not None:
            target = self.target_transform(target)
        return x, target

    def _float_tensor(self, arrays: dict[str, np.ndarray]) -> torch.Tensor:
        """The float32 input tensor (dtype="float32"), resized, written once into its final
        buffer: rgb resized while still uint8 (torch's antialiased uint8 path, about 3x faster
        than on float; values within one level), then copied into the buffer and scaled to
        [0, 1]."""
        size = self.size
        if self.modality == "depth":
            d = torch.from_numpy(np.ascontiguousarray(arrays["depth"])).unsqueeze(-3)
            return d if size is None else resize(d, size)
        rgb = torch.from_numpy(np.ascontiguousarray(arrays["rgb"])).movedim(-1, -3)
        if size is not None:
            rgb = resize(rgb, size)
        chans = 3 if self.modality == "rgb" else 4
        out = torch.empty((*rgb.shape[:-3], chans, *rgb.shape[-2:]), dtype=torch.float32)
        out[..., :3, :, :] = rgb  # uint8 -> float32 in the copy (measured 3x a fused mul)
        out[..., :3, :, :].mul_(1.0 / 255.0)
        if chans == 4:
            d = torch.from_numpy(np.ascontiguousarray(arrays["depth"]))
            out[..., 3, :, :] = d if size is None else resize(d.unsqueeze(-3), size)[..., 0, :, :]
        return out

    def _float_arrays(self, arrays: dict[str, np.ndarray]) -> dict[str, torch.Tensor]:
        """The target arrays of dtype="float32": resized with torch (contact nearest)."""
        out = {}
        for name in self.targets:
            a = torch.from_numpy(np.ascontiguousarray(arrays[name]))
            if self.size is not None:
                mode = "nearest" if name == "contact" else "bilinear"
                a = resize(a.unsqueeze(-3).to(torch.float32), self.size, mode).squeeze(-3)
                a = a > 0.5 if name == "contact" else a
            out[name] = a
        return out

    def _target(self, meta: dict[str, Any], spatial: dict[str, torch.Tensor]) -> dict[str, Any]:
        def num(v: float | None) -> float:
            return math.nan if v is None else float(v)

        t: dict[str, Any] = {"sample_id": meta["sample_id"], "class_idx": meta["class_idx"],
                             "press_depth_mm": num(meta["press_depth_mm"])}
        if self.view.kind == "slip":
            motion = meta["motion_mm"] or (math.nan, math.nan)
            t["state_idx"] = -1 if meta["state_idx"] is None else meta["state_idx"]
            t["direction"] = -1 if meta["direction"] is None else meta["direction"]
            t["motion_mm"] = torch.tensor(motion, dtype=torch.float32)
        for name in self.targets:
            t[name] = spatial[name]
        return t


def _int(v: Any) -> int | None:
    """A label as an int (a tensor or number), None for a missing one (-1 or None)."""
    if v is None:
        return None
    v = int(v)
    return None if v < 0 else v


def _wrap(x: Any, target: dict[str, Any]) -> dict[str, Any]:
    """The joint sample: {"image": x, **target}, as torchvision tv_tensors when torchvision is
    there (Image, or Video for T x C x H x W, each tensor of an rgbd dict; depth and contact
    targets as Mask)."""
    try:
        from torchvision import tv_tensors
    except ImportError:  # plain tensors for a callable that does not need torchvision
        return {"image": x, **target}

    def image(t: torch.Tensor) -> Any:
        return tv_tensors.Video(t) if t.ndim == 4 else tv_tensors.Image(t)

    sample: dict[str, Any] = dict(target)
    sample["image"] = {k: image(v) for k, v in x.items()} if isinstance(x, dict) else image(x)
    for name in TARGET_ARRAYS:
        if name in sample:
            sample[name] = tv_tensors.Mask(sample[name])
    return sample


def _plain(v: Any) -> Any:
    if isinstance(v, dict):
        return {k: _plain(a) for k, a in v.items()}
    return v.as_subclass(torch.Tensor) if isinstance(v, torch.Tensor) else v


def _unwrap(sample: dict[str, Any]) -> tuple[Any, dict[str, Any]]:
    """(x, target) of a joint sample, tv_tensors back to plain tensors."""
    sample = {k: _plain(v) for k, v in sample.items()}
    x = sample.pop("image")
    return x, sample


class HorizontalFlip:
    """A joint transform that mirrors a sample left-right with its labels: the image (each
    tensor of an rgbd dict), depth and contact, the slip direction (vtsbench.labels.MIRROR_X:
    right <-> left, up stays up) and the motion's x. A flip of the pixels alone would leave a
    slip sample's direction wrong.

    p: the probability of flipping; generator: a torch.Generator for reproducible draws.
    """

    def __init__(self, p: float = 0.5, generator: torch.Generator | None = None) -> None:
        if not 0 <= p <= 1:
            raise VtsError(f"p must be in [0, 1], got {p}")
        self.p, self.generator = p, generator

    def __repr__(self) -> str:
        return f"HorizontalFlip(p={self.p})"

    def __call__(self, sample: dict[str, Any]) -> dict[str, Any]:
        if self.p < 1 and float(torch.rand((), generator=self.generator)) >= self.p:
            return sample
        out = dict(sample)
        for name in ("image", *TARGET_ARRAYS):
            v = out.get(name)
            if isinstance(v, dict):
                out[name] = {k: a.flip(-1) for k, a in v.items()}
            elif v is not None:
                out[name] = v.flip(-1)
        d = out.get("direction")
        if d is not None and int(d) >= 0:
            out["direction"] = MIRROR_X[int(d)]
        if isinstance(out.get("motion_mm"), torch.Tensor):
            out["motion_mm"] = out["motion_mm"] * torch.tensor([-1.0, 1.0])
        return out


class TorchWindows(Loadable, Dataset):
    """(tensor, target) items of episode windows (`ds.episodes.windows(...).to_torch()`).

    x: rgb uint8 T x C x H x W, depth float32 mm T x 1 x H x W, rgbd a dict of the two, `size`
    resizing in the worker with OpenCV INTER_AREA (masks nearest) as TorchView does;
    dtype="float32" gives the same frames as float32 (`as_float`: rgb / 255, rgbd 4 channels).
    target: episode_id, episode_index, and T each: frame_index, timestamps (float64), state and
    direction (int64, -1 where unknown), pad_mask, and the arrays named in `targets` ("depth" in
    mm, "contact" bool) as T x H x W. A batch (`__getitems__`) is one `Windows.read` call (each
    frame read once however many of its windows hold it). Transforms and `loader` as in
    TorchView."""

    def __init__(self, windows: Windows, modality: str = "rgb",
                 size: Sequence[int] | None = None,
                 transform: Callable[[Any], Any] | None = None, targets: Sequence[str] = (),
                 transforms: Callable[[dict[str, Any]], dict[str, Any]] | None = None,
                 target_transform: Callable[[Any], Any] | None = None,
                 dtype: str = "uint8") -> None:
        _check_choices(modality, dtype, targets)
        from .arrays import check_arrays

        info = windows._data.store.info
        self.inputs = {"rgb": ("rgb",), "depth": ("depth",), "rgbd": ("rgb", "depth")}[modality]
        check_arrays(info, self.inputs, f"modality {modality!r}")
        for name in targets:
            check_arrays(info, (name,), f"target {name!r}")
        self.windows, self.modality, self.dtype = windows, modality, dtype
        self.size, self.targets = _check_size(size), tuple(targets)
        self.transform, self.transforms, self.target_transform = (transform, transforms,
                                                                  target_transform)
        self.arrays = tuple(dict.fromkeys(self.inputs + self.targets))

    def __len__(self) -> int:
        return len(self.windows)

    def __repr__(self) -> str:
        return (f"TorchWindows({len(self)} windows of {self.windows.length} frames, "
                f"modality={self.modality}, size={self.size}, dtype={self.dtype})")

    def __getitem__(self, i: int) -> tuple[Any, dict[str, Any]]:
        return tuple(self.__getitems__([i])[0])  # type: ignore[return-value]

    def __getitems__(self, items: Sequence[int]) -> list[tuple[Any, dict[str, Any]]]:
        """Several items from one `Windows.read` of their frames, written (resized, channels
        first) into the batch's tensors, of which the items are views (as TorchView's)."""
        items = [int(i) for i in items]
        if not items:
            return []
        b = self.windows.read(items, self.arrays)
        plain = self.dtype == "uint8" and self.transforms is None and self.transform is None \
            and self.target_transform is None
        shared = plain and in_worker()
        bufs = batch_tensors({n: b[n] for n in self.arrays}, len(items), self.inputs,
                              self.size, shared)
        for name, t in bufs.items():
            put_frames(name, b[name], t.numpy())
        whole = batch_of(bufs, self.inputs, self.modality, self.targets, shared)
        out = []
        for j in range(len(items)):
            x = item_at(whole.x, j)
            if self.dtype == "float32":
                x = as_float(x)
            target: dict[str, Any] = {
                "episode_id": b["episode_id"][j], "episode_index": int(b["episode_index"][j]),
                "frame_index": torch.from_numpy(b["frame_index"][j].copy()),
                "timestamps": torch.from_numpy(b["timestamps"][j].copy()),
                "state": torch.from_numpy(b["state"][j].astype(np.int64)),
                "direction": torch.from_numpy(b["direction"][j].astype(np.int64)),
                "pad_mask": torch.from_numpy(b["pad_mask"][j].copy())}
            target.update({n: t[j] for n, t in whole.spatial.items()})
            out.append(whole.add(x, target) if plain else self._item(x, target))
        return out

    _item = TorchView._item  # transforms, then transform, then target_transform
