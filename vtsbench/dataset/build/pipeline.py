"""`vtsbench build`: a recordings folder -> an RGB-D dataset, in whole-shard tasks, resumable.

The plan (samples, rows, shards) comes from the manifest alone. Every shard is one task that
decodes its samples' frames, makes depth and contact with the calibration, writes the shard
file of each array and then a marker holding the fingerprint of everything those bytes depend
on. A rerun keeps every shard whose marker still matches and redoes the others; the metadata,
index, splits and checksums are written last from the plan. Nothing depends on time, process
or worker count, so a resumed build, a process pool and a Dask cluster give the same bytes.

The steps live in modules of their own: options (the parameters), plan (samples, windows,
splits), shard (the task a worker runs), execute (process pool, Dask, worker tuning), staging
(partial folder, lock, resume) and finish (metadata, index, card, checksums, rename).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ...errors import VtsError
from ..format.layout import ARRAYS, KINDS, RGB_ONLY
from .execute import dask_client, process_pool, run_with_progress
from .finish import finish, write_plan_files
from .options import BuildOptions, check_options
from .plan import (
    Plan,
    add_given_splits,
    bad_error,
    frame_and_calibration,
    make_plan,
    plan_splits,
    resolve_calibration,
    screen_entries,
)
from .staging import (
    WORK,
    check_out,
    locked_stage,
    partial_path,
    recover,
    remove_stale,
    shard_done,
    shard_tasks,
)
from .store import samples_per_shard

__all__ = ["WORK", "BuildOptions", "BuildResult", "build", "partial_path"]


@dataclass
class BuildResult:
    """What `build` made, for the summary: counts, shards built and kept, skipped entries."""

    out: Path
    samples: dict[str, int]
    frames: dict[str, int]
    shards: dict[str, int]
    shards_built: int
    shards_kept: int
    skipped: dict[str, str]
    splits: list[str]
    splits_skipped: dict[str, str]
    bytes_on_disk: dict[str, int]
    seconds: float
    warnings: list[str] = field(default_factory=list)
    #: --store episodes: the takes stored (shards_built/kept then count takes written/kept)
    takes: int | None = None


def build(recordings: str | Path, out: str | Path, opts: BuildOptions | None = None,
          log: Callable[[str], None] | None = None) -> BuildResult:
    """Build the dataset of a recordings folder into OUT (atomic: complete or absent)."""
    from ...recordings.manifest import load_manifest

    opts = opts or BuildOptions()
    say = log or (lambda _msg: None)
    t0 = time.perf_counter()
    check_options(opts)
    root, out = Path(recordings).resolve(), Path(out).resolve()
    if opts.store == "episodes":  # each take stored once, the samples views of it
        from .episodes_build import build_episodes

        return BuildResult(**build_episodes(root, out, opts, say))
    recover(out)  # what a build killed in its final rename left: OUT's previous copy put back
    check_out(root, out, opts.overwrite)
    with ExitStack() as stack:
        # 1. workers: they start (and import) while this process reads the manifest, checks the
        # recordings and plans: 0.4 s sooner at work than when started after the manifest
        pool = (stack.enter_context(process_pool(opts.workers))
                if opts.workers > 1 and not opts.scheduler else None)
        # 2. inputs: the manifest, the entries that cannot be built, the calibration
        manifest = load_manifest(root)
        cal_path = resolve_calibration(root, opts.calibration) if opts.depth else None
        bad, warnings = screen_entries(root, manifest, opts.frames, max(2, opts.workers),
                                       opts.progress)
        cal, cal_sha, res, scale = frame_and_calibration(cal_path, manifest, bad)
        sps = {k: samples_per_shard(res, opts.frames if k == "slip" else None,
                                    int(opts.shard_mb * 2**20)) for k in KINDS}
        if bad and not opts.skip_bad:
            raise bad_error(bad)
        client = (stack.enter_context(dask_client(opts.scheduler, opts.workers))
                  if opts.scheduler else None)
        # 3. the partial folder, locked; OUT checked again under the lock: another build may
        # have finished it between the first check and taking the lock
        stage = stack.enter_context(locked_stage(out))
        check_out(root, out, opts.overwrite)
        kept, built, first = 0, 0, True
        previews: dict[str, Any] = {}
        while True:
            # 4. plan (again without the entries a shard task found bad) and splits: leaks
            # fail the build before the long part
            plan = make_plan(root, manifest, bad, frames=opts.frames, resolution=res,
                             mm_per_px=scale, samples_per_shard=sps,
                             level=opts.compression_level,
                             arrays=ARRAYS if opts.depth else RGB_ONLY)
            if not plan.samples:
                raise VtsError("nothing to build: no usable static or sequence entries "
                               "(calibration presses are not samples)", root)
            splits = plan_splits(plan, opts.seed)
            add_given_splits(splits, plan, opts)
            # 5. resume: keep the shards whose fingerprint still matches
            remove_stale(stage, plan)
            tasks = shard_tasks(plan, root, stage, cal_path, cal_sha, opts.solver)
            todo = [t for t in tasks if not shard_done(t)]
            if first:
                kept, first = len(tasks) - len(todo), False
                if kept:
                    say(f"resuming {partial_path(out).name}: {kept} of {len(tasks)} shards "
                        "already done")
            split_sha: dict[str, str] = {}

            def meanwhile(plan: Plan = plan, splits: Any = splits,
                          split_sha: dict[str, str] = split_sha) -> None:
                split_sha.update(write_plan_files(stage, plan, splits))

            # 6. the shard tasks; the plan's own files are written while they run
            late, written = run_with_progress(todo, tasks, opts, client, pool, meanwhile,
                                              previews)
            built += written
            if not late:
                break
            if not opts.skip_bad:
                raise bad_error(late)
            bad.update(late)  # plan again without them; shards before them stay valid
            previews.clear()  # the preview rows move with the plan
        # 7. metadata, card, checksums, rename to OUT
        result = finish(stage, out, plan, splits, split_sha, tasks, previews,
                        manifest=manifest, root=root, cal=cal, cal_sha=cal_sha,
                        cal_path=cal_path, opts=opts)
    return BuildResult(
        out=out, samples={k: plan.layouts[k].n for k in KINDS},
        frames={k: plan.layouts[k].n * (plan.layouts[k].frames or 1) for k in KINDS},
        shards={k: plan.layouts[k].n_shards for k in KINDS}, shards_built=built,
        shards_kept=kept, skipped=dict(sorted(bad.items())),
        splits=[s.name for s in splits.splits], splits_skipped=dict(splits.skipped),
        bytes_on_disk=result, seconds=time.perf_counter() - t0, warnings=warnings)
