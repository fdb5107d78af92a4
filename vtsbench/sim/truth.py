"""Ground-truth files: byte-deterministic .npz archives (fixed zip timestamps, fixed order)."""

from __future__ import annotations

import io
import zipfile
from pathlib import Path

import numpy as np

from .scene import Rendered

_EPOCH = (1980, 1, 1, 0, 0, 0)


def write_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write arrays as an .npz that np.load reads, with no timestamp (same data, same bytes)."""
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name, arr in arrays.items():
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.ascontiguousarray(arr), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=_EPOCH)
            info.external_attr = 0o644 << 16
            zf.writestr(info, buf.getvalue(), compress_type=zipfile.ZIP_DEFLATED,
                        compresslevel=1)


def write_truth(path: Path, rendered: Rendered) -> None:
    """Write a scene's truth: depth_mm (T,H,W), grad (T,H,W,2), contact (T,H,W), motion_px (T,2)."""
    write_npz(path, {"depth_mm": rendered.depth_mm, "grad": rendered.grad,
                     "contact": rendered.contact, "motion_px": rendered.motion_px})
