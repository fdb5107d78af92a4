"""`View.to_torch`: a torch Dataset of (tensor, target dict) over a view, for DataLoader workers.

Items read only the arrays their modality needs; a batch (DataLoader's `__getitems__`) is read
with one zarr call per contiguous run of rows. The Zarr arrays are opened lazily in each worker
process, never pickled. This module imports torch: import it only where torch is wanted.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
import torch.nn.functional as F
from torch.utils.data import Dataset

from ...errors import VtsError
from ...labels import DIRECTION_NAMES, MIRROR_X, STATES

if TYPE_CHECKING:
    from .view import View

MODALITIES = ("rgb", "depth", "rgbd")
TARGET_ARRAYS = ("depth", "contact")


def frame_numbers(t: int, k: int) -> np.ndarray:
    """k evenly spaced frames of a T-frame sequence, first and last included; k = 1 gives the
    last frame (the one press depth and contact centre describe)."""
    if not 1 <= k <= t:
        raise VtsError(f"frames must be in 1..{t} (frames per sequence), got {k}")
    if k == 1:
        return np.array([t - 1])
    return np.linspace(0, t - 1, k).round().astype(np.int64)


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
    uint8 stays uint8 (rounded)."""
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


class TorchView(Dataset):
    """(tensor, target) items of a view.

    tensor: rgb float32 in [0, 1] as C x H x W, depth float32 mm as one channel, rgbd both
    (4 channels); slip items are T x C x H x W. target: sample_id, class_idx, press_depth_mm
    (NaN when unknown) and for slip state_idx, direction (-1 when none) and motion_mm (2,),
    plus the arrays named in `targets` ("depth" in mm, "contact" bool) as (T x) H x W.

    Transforms, as in torchvision and TorchGeo: `transforms` gets the whole sample as one dict
    ({"image": tensor, **target}; with torchvision installed the tensor is a tv_tensors.Image,
    or a Video for a sequence, and the depth and contact targets are tv_tensors.Mask, so a
    torchvision.transforms.v2 transform moves them together) and returns it; then `transform`
    gets the tensor alone and `target_transform` the target.
    """

    def __init__(self, view: View, modality: str = "rgb", size: Sequence[int] | None = None,
                 frames: int | None = None, transform: Callable[[Any], Any] | None = None,
                 targets: Sequence[str] = (),
                 transforms: Callable[[dict[str, Any]], dict[str, Any]] | None = None,
                 target_transform: Callable[[Any], Any] | None = None) -> None:
        if modality not in MODALITIES:
            raise VtsError(f"unsupported modality {modality!r}; use one of "
                           f"{', '.join(MODALITIES)}")
        bad = [t for t in targets if t not in TARGET_ARRAYS]
        if bad:
            raise VtsError(f"unknown target array {bad[0]!r}; use {', '.join(TARGET_ARRAYS)}")
        if frames is not None and view.kind != "slip":
            raise VtsError("frames apply to slip sequences only")
        self.view, self.modality, self.transform = view, modality, transform
        self.transforms, self.target_transform = transforms, target_transform
        self.size = _check_size(size)
        self.targets = tuple(targets)
        t = view.dataset.info.frames_per_sequence
        self.frames = None if frames is None else frame_numbers(t, int(frames))
        inputs = {"rgb": ("rgb",), "depth": ("depth",), "rgbd": ("rgb", "depth")}[modality]
        from .arrays import check_arrays

        check_arrays(view.dataset.info, inputs, f"modality {modality!r}")
        for name in self.targets:
            check_arrays(view.dataset.info, (name,), f"target {name!r}")
        self.arrays = tuple(dict.fromkeys(inputs + self.targets))

    def __len__(self) -> int:
        return len(self.view)

    def __repr__(self) -> str:
        return (f"TorchView({self.view.kind}, {len(self)} samples, modality={self.modality}, "
                f"size={self.size}, frames={None if self.frames is None else len(self.frames)})")

    def __getitem__(self, i: int) -> tuple[Any, dict[str, Any]]:
        return self.__getitems__([i])[0]

    def __getitems__(self, items: Sequence[int]) -> list[tuple[Any, dict[str, Any]]]:
        """Several items read together (DataLoader calls this for a batch)."""
        items = [int(i) for i in items]
        arrays = self.view.read(items, self.arrays, frames=self.frames)
        metas = self.view.metas(items)
        return [self._item({n: a[k] for n, a in arrays.items()}, metas[k])
                for k in range(len(items))]

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
        x = torch.as_tensor(x).detach().cpu().float()
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

    def _item(self, arrays: dict[str, np.ndarray], meta: dict[str, Any]
              ) -> tuple[Any, dict[str, Any]]:
        x = self._tensor(arrays)
        target = self._target(arrays, meta)
        if self.transforms is not None:
            x, target = _unwrap(self.transforms(_wrap(x, target)))
        if self.transform is not None:
            x = self.transform(x)
        if self.target_transform is not None:
            target = self.target_transform(target)
        return x, target

    def _tensor(self, arrays: dict[str, np.ndarray]) -> torch.Tensor:
        """The input tensor, resized, written once into its final buffer.

        Full-size slip tensors are tens of MB and every pass over them is memory-bound: rgb is
        resized while still uint8 (torch's antialiased uint8 path, about 3x faster than on
        float; values within one level), then copied into the buffer and scaled to [0, 1].
        """
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

    def _target(self, arrays: dict[str, np.ndarray], meta: dict[str, Any]) -> dict[str, Any]:
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
            a = torch.from_numpy(np.ascontiguousarray(arrays[name]))
            if self.size is not None:
                mode = "nearest" if name == "contact" else "bilinear"
                a = resize(a.unsqueeze(-3).to(torch.float32), self.size, mode).squeeze(-3)
                a = a > 0.5 if name == "contact" else a
            t[name] = a
        return t


def _int(v: Any) -> int | None:
    """A label as an int (a tensor or number), None for a missing one (-1 or None)."""
    if v is None:
        return None
    v = int(v)
    return None if v < 0 else v


def _wrap(x: torch.Tensor, target: dict[str, Any]) -> dict[str, Any]:
    """The joint sample: {"image": x, **target}, as torchvision tv_tensors when torchvision is
    there (Image, or Video for T x C x H x W; depth and contact as Mask)."""
    try:
        from torchvision import tv_tensors
    except ImportError:  # plain tensors for a callable that does not need torchvision
        return {"image": x, **target}
    sample: dict[str, Any] = dict(target)
    sample["image"] = tv_tensors.Video(x) if x.ndim == 4 else tv_tensors.Image(x)
    for name in TARGET_ARRAYS:
        if name in sample:
            sample[name] = tv_tensors.Mask(sample[name])
    return sample


def _unwrap(sample: dict[str, Any]) -> tuple[Any, dict[str, Any]]:
    """(x, target) of a joint sample, tv_tensors back to plain tensors."""
    sample = {k: v.as_subclass(torch.Tensor) if isinstance(v, torch.Tensor) else v
              for k, v in sample.items()}
    x = sample.pop("image")
    return x, sample


class HorizontalFlip:
    """A joint transform that mirrors a sample left-right with its labels: the image, depth and
    contact, the slip direction (vtsbench.labels.MIRROR_X: right <-> left, up stays up) and the
    motion's x. A flip of the pixels alone would leave a slip sample's direction wrong.

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
            if name in out:
                out[name] = out[name].flip(-1)
        d = out.get("direction")
        if d is not None and int(d) >= 0:
            out["direction"] = MIRROR_X[int(d)]
        if isinstance(out.get("motion_mm"), torch.Tensor):
            out["motion_mm"] = out["motion_mm"] * torch.tensor([-1.0, 1.0])
        return out
