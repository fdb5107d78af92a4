"""What made a figure: library versions, torch threads and device (recorded in every
submission's metadata, hence in leaderboard entries), and the deterministic torch settings the
training loop and the recipes run under."""

from __future__ import annotations

import os
import platform
import sys
from typing import Any

#: Distributions whose versions can change a trained model's figures.
LIBRARIES = ("vtsbench", "numpy", "scipy", "torch", "torchvision", "transformers",
             "opencv-contrib-python-headless", "scikit-learn", "zarr")


def library_versions() -> dict[str, str]:
    """Installed versions (importlib.metadata: nothing is imported); absent ones left out."""
    from importlib.metadata import PackageNotFoundError, version

    out = {"python": platform.python_version()}
    for name in LIBRARIES:
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            continue
    return out


def environment(device: str | None = None) -> dict[str, Any]:
    """Library versions, plus torch's thread count when torch is loaded, and the device."""
    env: dict[str, Any] = {"libraries": library_versions(), "machine": platform.machine()}
    torch = sys.modules.get("torch")
    if torch is not None:
        env["torch_threads"] = torch.get_num_threads()
    if device is not None:
        env["device"] = device
    return env


def deterministic(threads: int | None = None) -> None:
    """Deterministic torch kernels (warn where an op has none), no cuDNN autotuning, and, when
    `threads` is given, that many CPU threads: the CPU kernels' reduction order depends on it."""
    import torch

    os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
    torch.use_deterministic_algorithms(True, warn_only=True)
    torch.backends.cudnn.benchmark = False
    torch.backends.cudnn.deterministic = True
    if threads:
        torch.set_num_threads(int(threads))
