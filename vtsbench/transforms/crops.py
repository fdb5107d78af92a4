"""Torch datasets of contact crops (`contact_crop`) of a view, cut once and kept in memory when
they fit (`CachedItems`): static frames for the ResNet recipe, sequences with their motion
channels for the TimeSformer recipe. The crop holds the imprint at the resolution it has on
the sensor, not shrunk with the whole frame."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import torch

from vtsbench.dataset.read.arrays import check_arrays
from vtsbench.dataset.read.torch_dataset import frame_numbers
from vtsbench.transforms.cache import CachedItems
from vtsbench.transforms.contact_crop import FLOW_SOFT_PX, contact_crop
from vtsbench.transforms.modality import channels_of


def crop_arrays(view: Any, modality: str) -> tuple[str, ...]:
    """The arrays a contact crop of `modality` reads: rgb (the crop's centre comes from it),
    depth for depth and rgbd, and the contact masks where the dataset has them."""
    need = ("rgb", "depth") if modality in ("depth", "rgbd") else ("rgb",)
    check_arrays(view.dataset.info, need, f"modality {modality!r}")
    return need + (("contact",) if "contact" in view.arrays else ())


class StaticCrops(CachedItems):
    """A static view as (x (C, S, S) float32, target {sample_id, class_idx}) cut around each
    frame's contact: `crop_px` sensor pixels resized to `size`."""

    def __init__(self, view: Any, crop_px: int, size: int, modality: str) -> None:
        super().__init__(view, channels_of(modality) * size * size * 4,
                         crop_arrays(view, modality))
        self.crop_px, self.size, self.modality = int(crop_px), size, modality

    def make(self, sample: dict[str, Any]) -> Any:
        s = sample
        seq = {"rgb": s["rgb"][None],
               "contact": None if s.get("contact") is None else s["contact"][None]}
        if "depth" in s:
            seq["depth"] = s["depth"][None]
        x, _ = contact_crop(seq, self.crop_px, self.size, self.modality)
        cls = -1 if s.get("class_idx") is None else int(s["class_idx"])
        return (torch.from_numpy(np.ascontiguousarray(x[0])),
                {"sample_id": s["sample_id"], "class_idx": torch.tensor(cls)})


class SequenceCrops(CachedItems):
    """A slip view as (x (T, C, S, S) float32, target {sample_id, state_idx, direction}) cut
    around each sequence's contact, `frames` evenly spaced frames kept; with `flow` (`shift` or
    `dis`) two more channels of motion from the first frame (`contact_crop`).

    `scale`: the model-input pixels per sensor pixel (x, y) of the last crop; `prep_s`: the
    seconds each sample's crop and motion channels took, by sample id (part of a latency from
    frames to labels)."""

    def __init__(self, view: Any, crop_px: int, size: int, frames: int, modality: str,
                 flow: str | None = None, soft_px: float = FLOW_SOFT_PX,
                 flow_mask: bool = False) -> None:
        chans = channels_of(modality) + 2 * (flow is not None)
        super().__init__(view, frames * chans * size * size * 4, crop_arrays(view, modality))
        self.crop_px, self.size, self.frames, self.modality = int(crop_px), size, frames, modality
        self.flow, self.soft_px, self.flow_mask = flow, soft_px, flow_mask
        self.scale: tuple[float, float] | None = None
        self.prep_s: dict[str, float] = {}

    def make(self, sample: dict[str, Any]) -> Any:
        s = sample
        t0 = time.perf_counter()
        x, self.scale = contact_crop(s, self.crop_px, self.size, self.modality, flow=self.flow,
                                     soft_px=self.soft_px, flow_mask=self.flow_mask)
        self.prep_s[s["sample_id"]] = time.perf_counter() - t0
        x = x[frame_numbers(len(x), self.frames)]
        state = -1 if s.get("state_idx") is None else int(s["state_idx"])
        direction = -1 if s.get("direction") is None else int(s["direction"])
        return (torch.from_numpy(np.ascontiguousarray(x)),
                {"sample_id": s["sample_id"], "state_idx": torch.tensor(state),
                 "direction": torch.tensor(direction)})
