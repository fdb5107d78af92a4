"""Finishing a build: zarr metadata, index and split files (while the shards are made), then
info.json, the build report, the card and preview, checksums, and the rename to OUT (commit:
the shard markers are kept until OUT holds the new dataset)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ...recordings.manifest import Manifest
from ..format.layout import (
    ARRAYS,
    BUILD_REPORT_PATH,
    CHECKSUMMED,
    DEPTH_DTYPE,
    DEPTH_SCALE_MM,
    INFO_PATH,
    KINDS,
    META_DIR,
    RGB_ONLY,
    SPLITS_DIR,
    group_path,
    index_path,
)
from ..format.provenance import package_version, sha256_file, versions
from ..splits.schemes import SplitReport
from .options import BuildOptions
from .plan import Plan
from .shard import ShardTask
from .staging import WORK, commit


def hash_files(stage: Path, select: Callable[[str], bool] = lambda _rel: True,
               known: dict[str, str] | None = None) -> dict[str, str]:
    """sha256 of the selected files under stage (relative '/' paths), never the build state;
    files in `known` (path -> sha256, from the shard markers) are not read again."""
    known = known or {}
    out = {}
    for p in sorted(stage.rglob("*")):
        rel = p.relative_to(stage).as_posix()
        if p.is_file() and not rel.startswith(f"{WORK}/") and select(rel):
            out[rel] = known[rel] if rel in known else sha256_file(p)
    return out


def shard_digests(stage: Path, tasks: list[ShardTask]) -> dict[str, str]:
    """sha256 of every shard file, from the markers the tasks wrote after their files (the
    workers hashed the bytes they wrote: 0.6 ms a frame at 480x640, in parallel)."""
    out = {}
    for t in tasks:
        doc = json.loads(Path(t.marker).read_text())
        for name in t.layout.arrays:
            path = Path(t.group_dir) / t.layout.shard_key(name, t.k)
            out[path.relative_to(stage).as_posix()] = doc["sha256"][name]
    return out


def _checksummed(rel: str) -> bool:
    """Files that dataset_sha256 covers."""
    return rel.startswith(CHECKSUMMED)


def build_params(manifest: Manifest, root: Path, cal_path: Path | None, opts: BuildOptions,
                 solver_note: str) -> dict[str, Any]:
    """The parameters recorded in info.json: what made the bytes, nothing about how it ran.
    Without depth (--no-depth) the depth, contact, calibration and solver are null."""
    from ...depth.depthmaps import CONTACT_PARAMS
    from ..format.arrays import DEPTH_MAX_MM, DEPTH_MIN_MM

    depth = cal_path is not None
    return {
        "recordings": {"name": manifest.name or root.name,
                       "manifest_sha256": sha256_file(root / "recordings.json"),
                       "entries": len(manifest.entries)},
        "arrays": list(ARRAYS if depth else RGB_ONLY),
        "calibration_file": cal_path.name if depth else None,
        "solver": opts.solver if depth else None, "frames": opts.frames,
        "compression_level": opts.compression_level, "shard_mb": opts.shard_mb,
        "seed": opts.seed, "skip_bad": opts.skip_bad,
        "depth": {"dtype": DEPTH_DTYPE, "scale_mm": DEPTH_SCALE_MM,
                  "clipped_to_mm": [DEPTH_MIN_MM, DEPTH_MAX_MM], "method": solver_note}
        if depth else None,
        "contact": {"method": "colour distance of the calibration's blurred difference to its "
                              "background, cleaned by vtsbench.depth.mask.clean_mask",
                    "params": CONTACT_PARAMS} if depth else None,
        "versions": versions(),
    }


def write_plan_files(stage: Path, plan: Plan, splits: SplitReport) -> dict[str, str]:
    """The files that depend on the plan alone (zarr metadata, index, split files), written
    while the shard tasks run; returns the splits' sha256."""
    from ...atomic import write_bytes_atomic
    from ..format.index import index_bytes
    from ..splits.files import write_splits
    from .store import write_metadata

    for kind in KINDS:
        write_metadata(stage / group_path(kind), plan.layouts[kind])
        path = stage / index_path(kind)
        path.parent.mkdir(parents=True, exist_ok=True)
        write_bytes_atomic(path, index_bytes(kind, plan.metas[kind], plan.extras.get(kind)))
    split_dir = stage / SPLITS_DIR
    names = {sp.name for sp in splits.splits}
    if split_dir.is_dir():
        for p in split_dir.glob("*.json"):
            if p.stem not in names:
                p.unlink()
    return write_splits(split_dir, splits.splits)


def finish(stage: Path, out: Path, plan: Plan, splits: SplitReport, split_sha: dict[str, str],
           tasks: list[ShardTask], previews: dict[str, Any], *, manifest: Manifest,
           root: Path, cal: Any, cal_sha: str, cal_path: Path | None,
           opts: BuildOptions) -> dict[str, int]:
    """Write everything but the shards and the plan files, checksum it, and rename the stage
    to OUT."""
    from ...atomic import write_bytes_atomic
    from ..format.info import Calibration, Counts, DatasetInfo, ZarrSettings, dataset_checksum
    from .card import write_card, write_preview

    lay = plan.layouts
    info = DatasetInfo(
        name=manifest.name or root.name, vtsbench_version=package_version(),
        frames_per_sequence=opts.frames, resolution=lay["static"].frame,
        objects=plan.objects, counts=Counts.of(plan.samples, splits.splits),
        shapes={k: {n: lay[k].shape(n) for n in lay[k].arrays} for k in KINDS},
        zarr=ZarrSettings({k: lay[k].samples_per_shard for k in KINDS},
                          "zstd" if opts.compression_level else "none", opts.compression_level),
        dataset_version=opts.version, created_by="vtsbench build",
        calibration=None if cal is None else Calibration(cal.sensor, cal.method, cal_sha),
        splits=split_sha,
        build=build_params(manifest, root, cal_path, opts,
                           "" if cal is None else f"{cal.method} + {opts.solver}"))
    content = hash_files(stage, _checksummed, shard_digests(stage, tasks))
    info.dataset_sha256 = dataset_checksum(content)
    write_preview(stage, plan, opts.workers, previews)
    report = {"built": {k: {"samples": lay[k].n, "frames": lay[k].n * (lay[k].frames or 1),
                            "shards": lay[k].n_shards} for k in KINDS},
              "skipped": [{"entry": e, "reason": r} for e, r in sorted(plan.bad.items())],
              "splits_skipped": dict(sorted(splits.skipped.items()))}
    (stage / META_DIR).mkdir(exist_ok=True)
    write_bytes_atomic(stage / BUILD_REPORT_PATH, (json.dumps(report, indent=1) + "\n").encode())
    write_card(stage, info, plan)
    info.files = {**content, **hash_files(
        stage, lambda rel: not _checksummed(rel) and rel != INFO_PATH)}
    write_bytes_atomic(stage / INFO_PATH, info.to_json().encode())
    sizes: dict[str, int] = {}
    for p in stage.rglob("*"):
        rel = p.relative_to(stage).as_posix()
        if p.is_file() and not rel.startswith(f"{WORK}/"):
            top = rel.split("/")[0] if "/" in rel else "."
            sizes[top] = sizes.get(top, 0) + p.stat().st_size
    commit(stage, out)  # --overwrite of a dataset (check_out): swapped, then deleted
    return dict(sorted(sizes.items()))
