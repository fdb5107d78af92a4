"""What made a dataset's bytes: file digests and the versions of the packages that shape them."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np


def sha256_file(path: Path) -> str:
    """sha256 of a file, read in 4 MiB blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(4 << 20):
            h.update(block)
    return h.hexdigest()



def versions() -> dict[str, str]:
    """Versions of what shapes the bytes: vtsbench, the codecs, numpy, OpenCV, pyarrow.

    From the installed packages' metadata where it can: importing zarr and pyarrow only for
    their version would cost the build process about 0.5 s before the first task starts.
    """
    import cv2

    return {"vtsbench": package_version(), "zarr": dist_version("zarr"),
            "numcodecs": dist_version("numcodecs"), "numpy": np.__version__,
            "opencv": cv2.__version__, "pyarrow": dist_version("pyarrow")}


def dist_version(name: str) -> str:
    """An installed package's version (its metadata; else its module's __version__)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(name)
    except PackageNotFoundError:
        import importlib

        return str(importlib.import_module(name).__version__)


def package_version() -> str:
    """The installed vtsbench version ('unknown' when running from a bare source tree)."""
    try:
        from importlib.metadata import version

        return version("vtsbench")
    except Exception:
        return "unknown"

