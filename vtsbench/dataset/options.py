"""The parameters of `vtsbench build` and their checks (one-line errors before any work)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..errors import VtsError

SOLVERS = ("dct", "dst", "masked")


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


def check_options(opts: BuildOptions) -> None:
    if opts.frames < 1:
        raise VtsError(f"--frames must be at least 1, got {opts.frames}")
    if opts.workers < 1:
        raise VtsError(f"--workers must be at least 1, got {opts.workers}")
    if opts.solver not in SOLVERS:
        raise VtsError(f"--solver must be one of {', '.join(SOLVERS)}, got {opts.solver!r}")
    if not opts.depth and opts.calibration is not None:
        raise VtsError("--calibration makes the depth; a build with --no-depth takes none")
    if not 0 <= opts.compression_level <= 22:
        raise VtsError(f"--compression-level must be 0 (none) to 22, got "
                       f"{opts.compression_level}")
    if not opts.shard_mb > 0:
        raise VtsError(f"--shard-mb must be positive, got {opts.shard_mb}")
    if opts.seed < 0:
        raise VtsError(f"--seed must be >= 0, got {opts.seed}")
    if not _semver(opts.version):
        raise VtsError(f"--dataset-version must be a semantic version such as 1.0.0, got "
                       f"{opts.version!r}")


def _semver(text: str) -> bool:
    import re

    return re.fullmatch(r"(0|[1-9]\d*)\.(0|[1-9]\d*)\.(0|[1-9]\d*)(-[0-9A-Za-z.-]+)?"
                        r"(\+[0-9A-Za-z.-]+)?", text) is not None
