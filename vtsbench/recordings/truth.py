"""Ground-truth files (`truth` of an entry): depth, gradients and contact per frame, in an .npz.

Stored cropped to the box outside which every array is zero, so a 480x640 frame whose contact
covers a tenth of it costs a tenth to compress and store; `read_truth` returns full frames.
Measured on one 480x640 slip sequence: full frames 0.7 MB and ~25 ms per frame to deflate;
cropped, see docs/benchmarks.md. Archives are byte-deterministic (fixed zip timestamps and order).
"""

from __future__ import annotations

import io
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import VtsError

_EPOCH = (1980, 1, 1, 0, 0, 0)
TRUTH_VERSION = 1


@dataclass
class Truth:
    """Exact ground truth of an entry's T frames (full frames)."""

    depth_mm: np.ndarray  # (T, H, W) float32, indentation into the gel, mm
    grad: np.ndarray  # (T, H, W, 2) float32, (d depth/dx, d depth/dy), y down the rows, mm/mm
    contact: np.ndarray  # (T, H, W) bool, where the gel touches the object
    motion_px: np.ndarray  # (T, 2) float32, object displacement from frame 0 (x right, y down)


def write_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write arrays as an .npz that np.load reads, with no timestamp (same data, same bytes)."""
    from ..atomic import replacing

    with replacing(path) as tmp, zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name, arr in arrays.items():
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.ascontiguousarray(arr), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=_EPOCH)
            info.external_attr = 0o644 << 16
            zf.writestr(info, buf.getvalue(), compress_type=zipfile.ZIP_DEFLATED,
                        compresslevel=1)


def nonzero_box(depth: np.ndarray, contact: np.ndarray, grad: np.ndarray) -> tuple[int, ...]:
    """(y0, y1, x0, x1): the smallest box holding every non-zero value of all frames."""
    any_nz = (depth != 0).any(axis=0) | contact.any(axis=0) | (grad != 0).any(axis=(0, 3))
    rows, cols = np.flatnonzero(any_nz.any(axis=1)), np.flatnonzero(any_nz.any(axis=0))
    if rows.size == 0:
        return (0, 0, 0, 0)
    return (int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1)


def write_truth(path: Path, truth: Truth) -> None:
    """Write truth cropped to its non-zero box, with the full shape to restore it."""
    y0, y1, x0, x1 = box = nonzero_box(truth.depth_mm, truth.contact, truth.grad)
    t, h, w = truth.depth_mm.shape
    write_npz(path, {
        "version": np.array(TRUTH_VERSION, np.int64),
        "shape": np.array([t, h, w], np.int64),
        "box": np.array(box, np.int64),
        "depth_mm": truth.depth_mm[:, y0:y1, x0:x1].astype(np.float32, copy=False),
        "grad": truth.grad[:, y0:y1, x0:x1].astype(np.float32, copy=False),
        "contact": truth.contact[:, y0:y1, x0:x1].astype(bool, copy=False),
        "motion_px": truth.motion_px.astype(np.float32, copy=False),
    })


def read_truth(path: Path) -> Truth:
    """Read a truth file back to full frames; one-line error if it is missing or malformed."""
    try:
        with np.load(path, allow_pickle=False) as z:
            t, h, w = (int(v) for v in z["shape"])
            y0, y1, x0, x1 = (int(v) for v in z["box"])
            depth = np.zeros((t, h, w), np.float32)
            grad = np.zeros((t, h, w, 2), np.float32)
            contact = np.zeros((t, h, w), bool)
            depth[:, y0:y1, x0:x1] = z["depth_mm"]
            grad[:, y0:y1, x0:x1] = z["grad"]
            contact[:, y0:y1, x0:x1] = z["contact"]
            return Truth(depth, grad, contact, z["motion_px"].astype(np.float32))
    except FileNotFoundError:
        raise VtsError("truth file not found", path) from None
    except (KeyError, ValueError, OSError, zipfile.BadZipFile) as e:
        raise VtsError(f"not a vtsbench truth file ({e})", path) from None
