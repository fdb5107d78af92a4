"""Moved to vtsbench.dataset.read.torch_dataset (it imports torch); re-exported here so that
imports of the old path keep working."""

from .read.torch_dataset import (
    MODALITIES,
    TARGET_ARRAYS,
    HorizontalFlip,
    TorchView,
    frame_numbers,
    resize,
)

__all__ = [
    "MODALITIES",
    "TARGET_ARRAYS",
    "HorizontalFlip",
    "TorchView",
    "frame_numbers",
    "resize",
]
