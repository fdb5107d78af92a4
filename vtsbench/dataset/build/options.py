"""The parameters of `vtsbench build` and their checks (one-line errors before any work)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ...errors import VtsError

SOLVERS = ("dct", "dst", "masked")
#: --store: samples (their own Zarr arrays, as always) or episodes (each take stored once,
#: the samples views of it: format 1.3, build/episodes_build.py).
STORES = ("samples", "episodes")
#: --video (with --store episodes): the codecs of format/video.py a build may store each
#: take's RGB with (lossless ffv1; lossy h264 and av1 at their stated quality).
VIDEOS = ("ffv1", "h264", "av1")


@dataclass(frozen=True)
class BuildOptions:
    """The parameters of `vtsbench build` (docs/dataset.md, Building)."""

    calibration: Path | None = None
    solver: str = "dct"
    depth: bool = True  # False: --no-depth, rgb arrays only and no calibration
    frames: int = 8
    workers: int = 1
    scheduler: str | None = None
    skip_bad: bool = False
    overwrite: bool = False
    version: str = "1.0.0"
    compression_level: int = 3
    seed: int = 0
    shard_mb: float = 32.0
    progress: bool = False
    #: --holdout-objects: a file of object names, one a line (split scheme given_objects).
    holdout_objects: Path | None = None
    #: --split-file: split schemes in schemas/split.schema.json given by the user.
    split_files: tuple[Path, ...] = ()
    #: --store: "samples" (default) or "episodes" (STORES).
    store: str = "samples"
    #: --video: None (RGB in Zarr) or a codec of VIDEOS, each take's RGB as one video file
    #: (--store episodes only; vtsbench.create's `video`).
    video: str | None = None


def check_options(opts: BuildOptions) -> None:
    """Every parameter in its range (vtsbench/limits.py), as one line naming the option."""
    from ...limits import (
        MAX_FRAMES,
        MAX_PATH_TEXT,
        MAX_SEED,
        MAX_SHARD_MB,
        MAX_VERSION,
        MAX_WORKERS,
        MIN_SHARD_MB,
        check_range,
        check_text,
    )

    check_range("--frames", opts.frames, 1, MAX_FRAMES)
    check_range("--workers", opts.workers, 1, MAX_WORKERS)
    if opts.store not in STORES:
        raise VtsError(f"--store must be one of {', '.join(STORES)}, got {opts.store!r:.40}")
    if opts.video is not None and opts.video not in VIDEOS:
        raise VtsError(f"--video must be one of {', '.join(VIDEOS)}, got {opts.video!r:.40}")
    if opts.video is not None and opts.store != "episodes":
        raise VtsError(f"--video {opts.video} stores each take's RGB as video: it needs --store "
                       "episodes (--store samples keeps every sample's frames in Zarr)")
    if opts.solver not in SOLVERS:
        raise VtsError(f"--solver must be one of {', '.join(SOLVERS)}, got {opts.solver!r}")
    if not opts.depth and opts.calibration is not None:
        raise VtsError("--calibration makes the depth; a build with --no-depth takes none")
    if not 0 <= opts.compression_level <= 22:
        raise VtsError(f"--compression-level must be 0 (none) to 22, got "
                       f"{opts.compression_level}")
    if not opts.shard_mb > 0:
        raise VtsError(f"--shard-mb must be positive, got {opts.shard_mb}")
    check_range("--shard-mb", opts.shard_mb, MIN_SHARD_MB, MAX_SHARD_MB)
    check_range("--seed", opts.seed, 0, MAX_SEED)
    check_text("--scheduler", opts.scheduler, MAX_PATH_TEXT)
    check_text("--dataset-version", opts.version, MAX_VERSION)
    if not _semver(opts.version):
        raise VtsError(f"--dataset-version must be a semantic version such as 1.0.0, got "
                       f"{opts.version!r}")


def _semver(text: str) -> bool:
    import re

    return re.fullmatch(r"(0|[1-9]\d*)\.(0|[1-9]\d*)\.(0|[1-9]\d*)(-[0-9A-Za-z.-]+)?"
                        r"(\+[0-9A-Za-z.-]+)?", text) is not None
