"""The shard task, run in the workers: decode a shard's samples, make depth and contact with
the calibration, encode and write one shard file per array, then its marker."""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import VtsError
from ..format.arrays import Layout
from ..format.layout import STORED_DTYPES
from ..format.provenance import sha256_file
from .plan import SampleSource


@dataclass(frozen=True)
class ShardTask:
    """One shard of one kind: everything a worker needs, as plain picklable values."""

    kind: str
    k: int
    root: str
    group_dir: str
    marker: str
    layout: Layout
    samples: tuple[SampleSource, ...]
    calibration: str
    calibration_sha: str
    solver: str
    fingerprint: str
    #: Rows of the shard (0-based within it) shown in the preview: the task returns their PNGs.
    preview: tuple[int, ...] = ()

    @property
    def n_frames(self) -> int:
        return len(self.samples) * (self.layout.frames or 1)


@dataclass
class ShardResult:
    """What a shard task did: frames written, or the entries it could not read."""

    kind: str
    k: int
    frames: int = 0
    nbytes: int = 0
    bad: dict[str, str] = field(default_factory=dict)
    #: PNGs of the preview rows (dataset row -> array -> one PNG per frame).
    previews: dict[int, dict[str, list[bytes]]] = field(default_factory=dict)


_CALIBRATIONS: dict[str, Any] = {}


def _calibration(path: str, sha: str) -> Any:
    """The calibration, loaded once per worker process (per file content)."""
    from ...depth.calibration import load_calibration

    if sha not in _CALIBRATIONS:
        if sha256_file(Path(path)) != sha:
            raise VtsError("calibration file changed during the build", path)
        _CALIBRATIONS.clear()
        _CALIBRATIONS[sha] = load_calibration(path)
    return _CALIBRATIONS[sha]


def _maker(cal: Any) -> Any:
    """The DepthMaker of a calibration, made once per process."""
    from ...depth.depthmaps import DepthMaker

    mk = cal.__dict__.get("_build_maker")
    if mk is None:
        mk = cal.__dict__["_build_maker"] = DepthMaker(cal)
    return mk


def depth_and_contact(rgb: np.ndarray, cal: Any, solver: str) -> tuple[np.ndarray, np.ndarray]:
    """Depth (mm, float32) and contact mask (bool) of RGB frames (T, H, W, 3), one per frame.

    The depth is reconstruct(rgb, cal, solver=solver)'s, bit for bit; the contact is the
    colour distance of the calibration's (blurred) difference to the background, cleaned
    (vtsbench.dataset.build.depthmaps.CONTACT_PARAMS).
    """
    mk = _maker(cal)
    depth = np.empty(rgb.shape[:-1], np.float32)
    contact = np.empty(rgb.shape[:-1], bool)
    for t, frame in enumerate(rgb):
        diff = mk.difference(frame)
        contact[t] = mk.contact(diff)
        depth[t] = mk.integrate(mk.gradients(diff), solver, contact[t])
    return depth, contact


def run_shard(task: ShardTask) -> ShardResult:
    """Decode, make depth and contact, encode and write one shard of each array, then mark it."""
    from ...recordings.media import read_frames
    from ..format.arrays import depth_to_int16
    from .store import write_json, write_shard

    marker = Path(task.marker)
    marker.unlink(missing_ok=True)  # the shard files are about to change
    lay, root = task.layout, Path(task.root)
    want = lay.sample_shape("rgb") if lay.frames else (1, *lay.sample_shape("rgb"))
    rgb = np.empty((len(task.samples), *lay.sample_shape("rgb")), STORED_DTYPES["rgb"])
    bad: dict[str, str] = {}
    for i, s in enumerate(task.samples):
        rows = rgb[i] if lay.frames else rgb[i:i + 1]  # decoded in place when they fit
        try:
            x = read_frames(root / s.path, s.start, s.stop, out=rows)
        except VtsError as e:
            bad[s.entry_id] = _relative(str(e), root)
            continue
        except Exception as e:  # OpenCV and decoders raise their own types
            bad[s.entry_id] = f"{s.path}: cannot decode frames [{s.start}, {s.stop}) ({e})"
            continue
        if x.shape != want:
            bad[s.entry_id] = (f"{s.path}: frames [{s.start}, {s.stop}) are "
                               f"{'x'.join(map(str, x.shape))}, expected "
                               f"{'x'.join(map(str, want))}")
            continue
        if x is not rows:
            rows[...] = x
    if bad:
        return ShardResult(task.kind, task.k, bad=bad)
    blocks = {"rgb": rgb}
    if "depth" in lay.arrays:
        mk = _maker(_calibration(task.calibration, task.calibration_sha))
        depth = blocks["depth"] = np.empty(rgb.shape[:-1], STORED_DTYPES["depth"])
        contact = blocks["contact"] = np.empty(rgb.shape[:-1], STORED_DTYPES["contact"])
        h, w = lay.frame
        flat_depth, flat_contact = depth.reshape(-1, h, w), contact.reshape(-1, h, w)
        for t, frame in enumerate(rgb.reshape(-1, h, w, 3)):  # as depth_and_contact
            diff = mk.difference(frame)
            flat_contact[t] = mk.contact(diff)
            z = mk.integrate(mk.gradients(diff), task.solver, flat_contact[t])
            depth_to_int16(z, out=flat_depth[t], scratch=True)
    _check_parent()
    digests: dict[str, str] = {}
    sizes = write_shard(Path(task.group_dir), lay, task.k, blocks, digests)
    marker.parent.mkdir(parents=True, exist_ok=True)
    write_json(marker, {"fingerprint": task.fingerprint, "sizes": sizes, "sha256": digests})
    return ShardResult(task.kind, task.k, frames=task.n_frames, nbytes=sum(sizes.values()),
                       previews=_previews(task, blocks))


def _previews(task: ShardTask, blocks: dict[str, np.ndarray]) -> dict[int, dict[str, list[bytes]]]:
    """PNGs of the task's preview rows, made here from the arrays in memory (in the workers,
    in parallel, instead of reading them back when the build finishes)."""
    from .card import frame_pngs

    first = task.layout.shard_rows(task.k).start
    return {first + i: {name: frame_pngs(name, blocks[name][i], task.layout.frames is not None)
                        for name in task.layout.arrays} for i in task.preview}


def _relative(text: str, root: Path) -> str:
    """An error line with the recordings folder's prefix taken off its path."""
    prefix = f"{root}{os.sep}"
    return text[len(prefix):] if text.startswith(prefix) else text


def limit_threads() -> None:
    """One OpenCV thread per worker: the workers already use every core (the depth's FFTs run
    with workers=1, shards are encoded in the calling thread, and spawned pool workers get one
    BLAS thread from their environment)."""
    import cv2

    cv2.setNumThreads(1)


#: The build process of a pool worker: a worker orphaned by a killed build writes nothing more,
#: so it cannot overwrite the shards of the next build in the same partial folder.
_PARENT: int | None = None


def pool_worker_init(parent: int) -> None:
    global _PARENT
    _PARENT = parent
    _watch_parent(parent)
    limit_threads()
    # Import what a shard task needs now (about 0.5 s of CPU), while the build process is still
    # checking the recordings and planning: the pool is started before that. (Shards are
    # encoded without zarr: store.encode_shard.)
    import google_crc32c  # noqa: F401
    import numcodecs.zstd  # noqa: F401
    import scipy.fft  # noqa: F401

    from ...depth import calibration, mapping, poisson  # noqa: F401
    from ...depth.depthmaps import DepthMaker  # noqa: F401
    from ...recordings import media  # noqa: F401
    from .store import write_shard  # noqa: F401


def _watch_parent(parent: int, every_s: float = 0.5) -> None:
    """A daemon thread that ends this worker when the build process is gone (kill -9 of the
    build: nobody shuts the pool down, and an idle worker would wait on its queue forever)."""
    import threading

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(every_s)
        os._exit(1)

    threading.Thread(target=watch, name="vtsbench-parent-watch", daemon=True).start()


def _check_parent() -> None:
    if _PARENT is not None and os.getppid() != _PARENT:
        raise SystemExit("vtsbench build: the build process is gone; this worker stops")
