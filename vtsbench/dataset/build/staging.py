"""The partial folder a build writes into: its lock, the shard tasks with the fingerprint of
everything their bytes depend on, which shards a rerun keeps (resume), what it deletes, and the
final rename that keeps the resume state until OUT holds the new dataset (commit, recover)."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from ...atomic import TMP_SUFFIX
from ...errors import VtsError
from ..format.layout import ARRAYS, INFO_PATH, KINDS, group_path
from ..format.provenance import sha256_file, versions
from .plan import Plan, SampleSource
from .shard import ShardTask

#: Bumped whenever the bytes a shard task writes change for the same inputs.
FINGERPRINT_VERSION = 2
#: Build state inside the partial folder (shard markers); parked beside it during the final
#: rename (commit) and deleted once the rename has happened.
WORK = ".build"
#: The state an episode writer (build/writer.py) keeps in WORK instead of shard markers.
WRITER_STATE = "writer.json"


class SourceStats:
    """Size and modification time of source files (folders listed once): a cheap change test."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self._folders: dict[str, list[Path]] = {}

    def of(self, src: SampleSource) -> list[Any]:
        from ...recordings.media import folder_frames

        path = self.root / src.path
        try:
            if path.is_dir():
                if src.path not in self._folders:
                    self._folders[src.path] = folder_frames(path)
                files = self._folders[src.path][src.start:src.stop]
                return [[f.name, *self._stat(f)] for f in files]
            return self._stat(path)
        except OSError:
            return ["missing"]

    @staticmethod
    def _stat(path: Path) -> list[int]:
        st = path.stat()
        return [st.st_size, st.st_mtime_ns]


def shard_tasks(plan: Plan, root: Path, stage: Path, calibration: Path | None, cal_sha: str,
                solver: str) -> list[ShardTask]:
    """One task per shard of each kind, with the fingerprint of everything its bytes use."""
    stats = SourceStats(root)
    from ...depth.depthmaps import CONTACT_PARAMS
    from .card import PREVIEW_SAMPLES, preview_rows

    depth = "depth" in plan.layouts["static"].arrays
    base = {"version": FINGERPRINT_VERSION, "versions": versions(), "calibration": cal_sha,
            "solver": solver if depth else None, "contact": CONTACT_PARAMS if depth else None,
            "arrays": list(plan.layouts["static"].arrays)}
    tasks = []
    for kind in KINDS:
        lay = plan.layouts[kind]
        group = stage / group_path(kind)
        shown = set(preview_rows(lay.n, PREVIEW_SAMPLES[kind]))
        for k in range(lay.n_shards):
            rows = lay.shard_rows(k)
            samples = tuple(plan.sources[kind][r] for r in rows)
            doc = {**base, "kind": kind, "k": k, "frame": list(lay.frame), "frames": lay.frames,
                   "samples_per_shard": lay.samples_per_shard, "level": lay.level,
                   "samples": [[s.sample_id, s.path, s.start, s.stop, stats.of(s)]
                               for s in samples]}
            fp = hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()
            tasks.append(ShardTask(kind, k, str(root), str(group), str(_marker(stage, kind, k)),
                                   lay, samples, "" if calibration is None else str(calibration),
                                   cal_sha, solver, fp,
                                   tuple(i for i, r in enumerate(rows) if r in shown)))
    return tasks


def _marker(stage: Path, kind: str, k: int) -> Path:
    return stage / WORK / "shards" / f"{kind}-{k:06d}.json"


def shard_done(task: ShardTask) -> bool:
    """True when the shard's marker holds this task's fingerprint and its files are there."""
    try:
        doc = json.loads(Path(task.marker).read_text())
    except (OSError, ValueError):
        return False
    if doc.get("fingerprint") != task.fingerprint or not isinstance(doc.get("sha256"), dict):
        return False
    group = Path(task.group_dir)
    sizes = doc.get("sizes", {})
    for name in task.layout.arrays:
        p = group / task.layout.shard_key(name, task.k)
        if not p.is_file() or p.stat().st_size != sizes.get(name):
            return False
    return True


def partial_path(out: Path) -> Path:
    """The hidden folder a build writes into: `.OUT.partial` beside OUT."""
    return out.with_name(f".{out.name}.partial")


def lock_path(out: Path) -> Path:
    """`.OUT.lock` beside OUT: the lock of every build or export writing OUT (an empty file,
    removed by its holder; one left by a killed process is taken over)."""
    return out.with_name(f".{out.name}.lock")


#: The record commit leaves in the parked resume state: the sha256 of the stage's info.json.
COMMIT = "commit.json"


@contextmanager
def locked_stage(out: Path, stage: Path | None = None, work: str = WORK,
                 create: bool = True) -> Iterator[Path]:
    """Create or reuse the partial folder (`.OUT.partial`, or `stage`) with its state folder
    `work`, holding a lock so two builds never share it; what a killed run left beside OUT is
    first put right (recover_stage). create=False: only that (see recover)."""
    stage = stage or partial_path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    # The lock lives beside OUT, not in the partial folder: it is held from before the existence
    # check (build re-runs check_out under it) through the final rename, and a second build
    # cannot take it while the first parks its build state and renames the folder. The holder
    # removes the file before letting go; a build that locked a file already removed (opened
    # just before) sees that it is no longer the one at the path and stops.
    path = lock_path(out)
    fh = open(path, "a+b")  # noqa: SIM115 (held for the whole block)
    held = False
    try:
        try:
            import fcntl

            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
            held = True
            if not path.exists() or os.stat(path).st_ino != os.fstat(fh.fileno()).st_ino:
                held = False
                raise OSError("lock file replaced")
        except ImportError:  # no fcntl (Windows): no lock
            pass
        except OSError:
            raise VtsError("another build or export is writing this dataset (its lock is "
                           "held)", out) from None
        recover_stage(out, stage, work)
        if create:
            (stage / work).mkdir(parents=True, exist_ok=True)
        yield stage
    finally:
        if held:
            path.unlink(missing_ok=True)
        fh.close()


def parked_path(stage: Path, work: str = WORK) -> Path:
    """Where commit parks the stage's state folder during the final rename: beside the stage
    (`.OUT.partial.build`), so OUT never holds it and a kill never loses it."""
    return stage.with_name(f"{stage.name}{work}")


def commit(stage: Path, out: Path, work: str = WORK) -> None:
    """Rename the finished stage to OUT (atomic.replace_dir: OUT is at every instant the
    previous complete copy or the new one), keeping its resume state until that has happened.

    The state folder (shard markers) is parked beside the stage with the sha256 of the stage's
    info.json, then the stage is renamed, then the state deleted. A run that finds the state
    parked (recover_stage) puts it back when the stage still holds that info.json (the rename
    had not happened: every shard is kept) and deletes it otherwise.
    """
    from ...atomic import rename, replace_dir, write_bytes_atomic

    parked = parked_path(stage, work)
    shutil.rmtree(parked, ignore_errors=True)
    write_bytes_atomic(stage / work / COMMIT,
                       json.dumps({"info_sha256": sha256_file(stage / INFO_PATH)}).encode())
    rename(stage / work, parked)
    replace_dir(stage, out)
    shutil.rmtree(parked, ignore_errors=True)


def recover_stage(out: Path, stage: Path, work: str = WORK) -> None:
    """Put right what a run killed in commit left (under the lock): OUT's previous copy back
    when OUT is missing (atomic.recover_dir), the parked state back into a stage not yet
    renamed, and otherwise the parked state and the previous copy under the stage's name
    deleted. Nothing is left beside OUT that no run would use."""
    from ...atomic import recover_dir, rename

    recover_dir(out, INFO_PATH)
    parked = parked_path(stage, work)
    if not parked.is_dir():
        return
    if stage.is_dir() and not (stage / work).exists():
        try:
            want = json.loads((parked / COMMIT).read_text())["info_sha256"]
            same = sha256_file(stage / INFO_PATH) == want
        except (OSError, ValueError, KeyError, TypeError):
            same = False
        if same:
            rename(parked, stage / work)
            return
        shutil.rmtree(stage, ignore_errors=True)  # the previous copy, swapped out of OUT
    shutil.rmtree(parked, ignore_errors=True)


def recover(out: Path, stage: Path | None = None, work: str = WORK) -> None:
    """recover_stage before anything looks at OUT, when the lock is free (a run holding it is
    alive and finishes its own rename)."""
    if not out.parent.is_dir():
        return
    try:
        with locked_stage(out, stage, work, create=False):
            pass
    except (VtsError, OSError):
        pass


def remove_stale(stage: Path, plan: Plan) -> None:
    """Delete shard files and markers the plan has no place for (and the arrays it has none
    for), and left-over temporaries."""
    if (stage / WORK / WRITER_STATE).exists():  # never delete a writer's saved episodes
        raise VtsError("holds a partial dataset of episodes (vtsbench.create), not a build: "
                       "finish it with vtsbench.create(..., resume=True) or delete it", stage)
    for kind in KINDS:
        lay = plan.layouts[kind]
        group = stage / group_path(kind)
        keep = {group / lay.shard_key(n, k) for n in lay.arrays for k in range(lay.n_shards)}
        for name in ARRAYS:
            if name not in lay.arrays and (group / name).is_dir():  # --no-depth after depth
                shutil.rmtree(group / name)
                continue
            chunks = group / name / "c"
            if chunks.is_dir():
                for p in chunks.rglob("*"):
                    if p.is_file() and p not in keep:
                        p.unlink()
        shards = stage / WORK / "shards"
        if shards.is_dir():
            for p in shards.glob(f"{kind}-*.json"):
                if int(p.stem.split("-")[1]) >= lay.n_shards:
                    p.unlink()
    for p in stage.rglob(f"*{TMP_SUFFIX}"):
        if p.name.startswith(".") and p.is_file():
            p.unlink()


def check_out(root: Path, out: Path, overwrite: bool) -> None:
    """Refuse an existing OUT without --overwrite, and any OUT that --overwrite could make
    destroy something other than a dataset: the recordings, or a folder that is not one."""
    if out == root or root in out.parents:
        raise VtsError("OUT must not be inside the recordings folder", out)
    if out in root.parents:
        raise VtsError("the recordings folder is inside OUT; choose another OUT", out)
    if not out.exists() and not out.is_symlink():
        return
    if not overwrite:
        raise VtsError("already exists (use --overwrite to replace it)", out)
    if not out.is_dir() or (any(out.iterdir()) and not (out / INFO_PATH).is_file()):
        raise VtsError(f"exists and is not a vtsbench dataset (no {INFO_PATH}); --overwrite "
                       "replaces only datasets: remove it yourself or choose another OUT", out)
