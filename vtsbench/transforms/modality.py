"""The input modalities of the models and their channel counts: rgb 3, depth 1, rgbd 4 (depth
last), the one table the augmentation and the networks' first layers are sized from."""

from __future__ import annotations

from vtsbench.errors import VtsError

CHANNELS = {"rgb": 3, "depth": 1, "rgbd": 4}


def channels_of(modality: str) -> int:
    """Number of input channels of a modality: rgb 3, depth 1, rgbd 4."""
    if modality not in CHANNELS:
        raise VtsError(f"unknown modality {modality!r}; expected one of {sorted(CHANNELS)}")
    return CHANNELS[modality]
