"""`vtsbench build`: a recordings folder -> an RGB-D dataset, in whole-shard tasks, resumable.

The plan (samples, rows, shards) comes from the manifest alone. Every shard is one task that
decodes its samples' frames, makes depth and contact with the calibration, writes the shard
file of each array and then a marker holding the fingerprint of everything those bytes depend
on. A rerun keeps every shard whose marker still matches and redoes the others; the metadata,
index, splits and checksums are written last from the plan. Nothing depends on time, process
or worker count, so a resumed build, a process pool and a Dask cluster give the same bytes.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import VtsError
from ..recordings.manifest import Entry, Manifest
from .schema import SampleMeta
from .store import ARRAYS, KINDS, RGB_ONLY, TMP_SUFFIX, Layout

CALIBRATION_NAME = "calibration.safetensors"
#: Bumped whenever the bytes a shard task writes change for the same inputs.
FINGERPRINT_VERSION = 2
#: Build state inside the partial folder (markers, lock); removed before the final rename.
WORK = ".build"
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


@dataclass(frozen=True)
class SampleSource:
    """Where one sample's frames are: its entry, the source path and the frame range."""

    entry_id: str
    sample_id: str
    path: str
    start: int
    stop: int


@dataclass
class Plan:
    """Samples of both kinds in row order, their sources, array layouts, and bad entries."""

    metas: dict[str, list[SampleMeta]]
    sources: dict[str, list[SampleSource]]
    layouts: dict[str, Layout]
    objects: list[str]
    bad: dict[str, str]
    #: Extra index columns per kind (column -> a value per row): the entries' take and meta.
    extras: dict[str, dict[str, list[str | None]]] = field(default_factory=dict)

    @property
    def samples(self) -> list[SampleMeta]:
        return [m for k in KINDS for m in self.metas[k]]


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


# -- inputs ---------------------------------------------------------------------------------


def resolve_calibration(root: Path, path: Path | None) -> Path:
    """The calibration file: --calibration, else RECORDINGS/calibration.safetensors."""
    if path is not None:
        if not Path(path).is_file():
            raise VtsError("calibration file not found", path)
        return Path(path).resolve()
    default = root / CALIBRATION_NAME
    if not default.is_file():
        raise VtsError(f"no calibration: make one with `vtsbench calibrate {root} --out "
                       f"{default}` (or pass --calibration FILE), or build RGB only with "
                       "--no-depth")
    return default.resolve()


def sha256_file(path: Path) -> str:
    """sha256 of a file, read in 4 MiB blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(4 << 20):
            h.update(block)
    return h.hexdigest()


def screen_entries(root: Path, manifest: Manifest, frames: int,
                   workers: int = 2, progress: bool = False) -> tuple[dict[str, str], list[str]]:
    """Bad sample entries (id -> reason) found cheaply up front, and warnings.

    Reuses `vtsbench check` (files present and decodable at the ends of each range, sizes,
    labels), except that PNG frames are sized from their headers, not decoded: the shard tasks
    decode every frame anyway and report one that does not decode (decoding each static frame
    twice cost a fifth of their decoding; 1.2 s of CPU for 260 480x640 frames); a problem that
    belongs to no entry (a duplicate id) is an error for the whole build. Adds what a build
    needs beyond a valid folder: an object name, T frames.
    """
    from ..recordings.check import check_folder

    report = check_folder(root, deep=False, workers=max(1, workers), decode=False,
                          progress=progress)
    kinds = {e.id: e.kind for e in manifest.entries}
    per: dict[str, list[str]] = {}
    warnings = list(report.warnings)
    for p in report.problems:
        eid, sep, rest = p.partition(": ")
        if sep and eid in kinds:
            if rest.endswith("truth file not found"):  # the build does not read truth files
                warnings.append(p)
            elif kinds[eid] != "press":  # presses are not samples (they made the calibration)
                per.setdefault(eid, []).append(rest)
        elif p.startswith("session "):
            warnings.append(p)
        else:
            more = len(report.problems) - 1
            raise VtsError(p + (f" (and {more} more problems; run `vtsbench check`)"
                                if more else ""))
    for e in manifest.entries:
        if e.kind == "press" or e.id in per:
            continue
        if not e.object:
            per[e.id] = ["no object name (class_idx and the splits need one)"]
        elif e.kind == "sequence":
            n = _sequence_length(root, e)
            if n < frames:
                per[e.id] = [f"{e.source.path}: sequence of {n} frames is shorter than "
                             f"--frames {frames}"]
    return {k: "; ".join(v) for k, v in per.items()}, warnings


def _sequence_length(root: Path, e: Entry) -> int:
    from ..recordings.media import probe

    start = e.source.start or 0
    stop = (e.source.stop if e.source.stop is not None
            else probe(root / e.source.path, decode=False).n_frames)
    return max(0, stop - start)


# -- plan -----------------------------------------------------------------------------------


def _windows(root: Path, e: Entry, frames: int) -> list[tuple[str, int, int]]:
    """(sample id, start, stop) of each sample of an entry."""
    if e.kind == "static":
        f = e.source.frame or 0
        return [(e.id, f, f + 1)]
    start = e.source.start or 0
    n = _sequence_length(root, e) // frames
    if n == 1:
        return [(e.id, start, start + frames)]
    return [(f"{e.id}-w{k:03d}", start + k * frames, start + (k + 1) * frames) for k in range(n)]


def make_plan(root: Path, manifest: Manifest, bad: dict[str, str], *, frames: int,
              resolution: tuple[int, int], mm_per_px: tuple[float, float] | None,
              samples_per_shard: dict[str, int], level: int,
              arrays: tuple[str, ...] = ARRAYS) -> Plan:
    """Samples in manifest order (windows in order), rows, class indices and layouts.

    mm_per_px: the calibration's, for sessions that have none (None without a calibration:
    their samples' scale is then unknown, null in the index)."""
    rows: dict[str, list[tuple[dict[str, Any], SampleSource]]] = {k: [] for k in KINDS}
    for e in manifest.entries:
        if e.kind == "press" or e.id in bad:
            continue
        kind = "static" if e.kind == "static" else "slip"
        ses = manifest.session(e.session)
        mx, my = ses.mm_per_px or mm_per_px or (None, None)
        lab = e.labels
        for sid, a, b in _windows(root, e, frames):
            d: dict[str, Any] = {
                "sample_id": sid, "kind": kind, "object": e.object, "session": ses.id,
                "sensor": ses.sensor, "mm_per_px_x": None if mx is None else float(mx),
                "mm_per_px_y": None if my is None else float(my),
                "source": f"{e.source.path}[{a}:{b}]", "press_depth_mm": lab.press_depth_mm,
                "contact_x_px": None if lab.contact_px is None else lab.contact_px[0],
                "contact_y_px": None if lab.contact_px is None else lab.contact_px[1]}
            if kind == "slip":
                d.update(state=lab.state, direction=lab.direction if lab.state == "slip" else None,
                         motion_dx_mm=None if lab.motion_mm is None else lab.motion_mm[0],
                         motion_dy_mm=None if lab.motion_mm is None else lab.motion_mm[1])
            rows[kind].append((d, SampleSource(e.id, sid, e.source.path, a, b)))
    seen: dict[str, str] = {}
    for kind in KINDS:
        for d, src in rows[kind]:
            if d["sample_id"] in seen:
                raise VtsError(f"sample id {d['sample_id']!r} of entry {src.entry_id} is also "
                               f"made by entry {seen[d['sample_id']]} (ids must be unique)")
            seen[d["sample_id"]] = src.entry_id
    objects = sorted({d["object"] for kind in KINDS for d, _ in rows[kind]})
    metas = {kind: [SampleMeta(**d, row=i, class_idx=objects.index(d["object"]))
                    for i, (d, _) in enumerate(rows[kind])] for kind in KINDS}
    layouts = {kind: Layout(kind, len(rows[kind]), resolution,
                            frames if kind == "slip" else None, samples_per_shard[kind], level,
                            arrays)
               for kind in KINDS}
    return Plan(metas, {k: [s for _, s in rows[k]] for k in KINDS}, layouts, objects,
                dict(bad), extra_columns(manifest, {k: [s for _, s in rows[k]] for k in KINDS}))


def extra_columns(manifest: Manifest, sources: dict[str, list[SampleSource]]
                  ) -> dict[str, dict[str, list[str | None]]]:
    """The recordings' own fields as extra index columns per kind: an entry's `take` and every
    key of its `meta` (pattern fields such as camera or split), as strings, None where absent."""
    from .schema import extra_column_name

    entries = {e.id: e for e in manifest.entries}
    out: dict[str, dict[str, list[str | None]]] = {}
    for kind, srcs in sources.items():
        fields: list[dict[str, str]] = []
        for src in srcs:
            e = entries[src.entry_id]
            got = {} if e.take is None else {"take": str(e.take)}
            for k, v in sorted((e.meta or {}).items()):
                name = extra_column_name(k)
                if name is not None and v is not None:
                    got.setdefault(name, v if isinstance(v, str) else
                                   json.dumps(v, sort_keys=True, ensure_ascii=False))
            fields.append(got)
        names = sorted({n for f in fields for n in f})
        out[kind] = {n: [f.get(n) for f in fields] for n in names}
    return out


# -- fingerprints ---------------------------------------------------------------------------


def _versions() -> dict[str, str]:
    """Versions of what shapes the bytes: vtsbench, the codecs, numpy, OpenCV, pyarrow.

    From the installed packages' metadata where it can: importing zarr and pyarrow only for
    their version would cost the build process about 0.5 s before the first task starts.
    """
    import cv2

    return {"vtsbench": package_version(), "zarr": _dist_version("zarr"),
            "numcodecs": _dist_version("numcodecs"), "numpy": np.__version__,
            "opencv": cv2.__version__, "pyarrow": _dist_version("pyarrow")}


def _dist_version(name: str) -> str:
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


class SourceStats:
    """Size and modification time of source files (folders listed once): a cheap change test."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self._folders: dict[str, list[Path]] = {}

    def of(self, src: SampleSource) -> list[Any]:
        from ..recordings.media import folder_frames

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
    from .card import PREVIEW_SAMPLES, preview_rows
    from .depthmaps import CONTACT_PARAMS

    depth = "depth" in plan.layouts["static"].arrays
    base = {"version": FINGERPRINT_VERSION, "versions": _versions(), "calibration": cal_sha,
            "solver": solver if depth else None, "contact": CONTACT_PARAMS if depth else None,
            "arrays": list(plan.layouts["static"].arrays)}
    tasks = []
    for kind in KINDS:
        lay = plan.layouts[kind]
        group = stage / "data" / f"{kind}.zarr"
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


# -- shard tasks (run in workers) ------------------------------------------------------------

_CALIBRATIONS: dict[str, Any] = {}


def _calibration(path: str, sha: str) -> Any:
    """The calibration, loaded once per worker process (per file content)."""
    from ..depth.calibration import load_calibration

    if sha not in _CALIBRATIONS:
        if sha256_file(Path(path)) != sha:
            raise VtsError("calibration file changed during the build", path)
        _CALIBRATIONS.clear()
        _CALIBRATIONS[sha] = load_calibration(path)
    return _CALIBRATIONS[sha]


def _maker(cal: Any) -> Any:
    """The DepthMaker of a calibration, made once per process."""
    from .depthmaps import DepthMaker

    mk = cal.__dict__.get("_build_maker")
    if mk is None:
        mk = cal.__dict__["_build_maker"] = DepthMaker(cal)
    return mk


def depth_and_contact(rgb: np.ndarray, cal: Any, solver: str) -> tuple[np.ndarray, np.ndarray]:
    """Depth (mm, float32) and contact mask (bool) of RGB frames (T, H, W, 3), one per frame.

    The depth is reconstruct(rgb, cal, solver=solver)'s, bit for bit; the contact is the
    colour distance of the calibration's (blurred) difference to the background, cleaned
    (vtsbench.dataset.depthmaps.CONTACT_PARAMS).
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
    from ..recordings.media import read_frames
    from .store import depth_to_int16, write_json, write_shard

    marker = Path(task.marker)
    marker.unlink(missing_ok=True)  # the shard files are about to change
    lay, root = task.layout, Path(task.root)
    want = lay.sample_shape("rgb") if lay.frames else (1, *lay.sample_shape("rgb"))
    rgb = np.empty((len(task.samples), *lay.sample_shape("rgb")), np.uint8)
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
        depth = blocks["depth"] = np.empty(rgb.shape[:-1], np.int16)
        contact = blocks["contact"] = np.empty(rgb.shape[:-1], bool)
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


def _limit_threads() -> None:
    """One OpenCV thread per worker: the workers already use every core (the depth's FFTs run
    with workers=1, shards are encoded in the calling thread, and spawned pool workers get one
    BLAS thread from their environment)."""
    import cv2

    cv2.setNumThreads(1)


#: The build process of a pool worker: a worker orphaned by a killed build writes nothing more,
#: so it cannot overwrite the shards of the next build in the same partial folder.
_PARENT: int | None = None


def _pool_worker_init(parent: int) -> None:
    global _PARENT
    _PARENT = parent
    _watch_parent(parent)
    _limit_threads()
    # Import what a shard task needs now (about 0.5 s of CPU), while the build process is still
    # checking the recordings and planning: the pool is started before that. (Shards are
    # encoded without zarr: store.encode_shard.)
    import google_crc32c  # noqa: F401
    import numcodecs.zstd  # noqa: F401
    import scipy.fft  # noqa: F401

    from ..depth import calibration, mapping, poisson  # noqa: F401
    from ..recordings import media  # noqa: F401
    from . import depthmaps, store  # noqa: F401


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


# -- executors ------------------------------------------------------------------------------

#: The environment of spawned workers: one BLAS/OpenMP thread, and glibc's malloc keeping the
#: memory it frees (large blocks from the heap, never trimmed) instead of mapping fresh pages
#: for every frame-sized array and returning them: the page faults cost about a tenth of a
#: shard task here (480x640 slip shard, one worker: 21.5 -> 19 ms a frame, best of 8 tasks).
#: A worker's memory then stays at its peak (about 0.3 GB at 480x640) until the build ends.
_WORKER_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
               "MALLOC_MMAP_THRESHOLD_": str(1 << 30), "MALLOC_TRIM_THRESHOLD_": str(1 << 30)}


@contextmanager
def _worker_env() -> Iterator[None]:
    """Children spawned inside the block start with _WORKER_ENV."""
    old = {k: os.environ.get(k) for k in _WORKER_ENV}
    os.environ.update(_WORKER_ENV)
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


@contextmanager
def _malloc_keeps_memory() -> Iterator[None]:
    """_WORKER_ENV's malloc settings for this process (glibc's mallopt), while the shard tasks
    run in it. Afterwards the free memory is released and the thresholds set where glibc's own
    adjustment takes them in a process that frees large arrays (32 MiB, trimming above 64 MiB):
    a setting disables that adjustment, and at the 128 KiB default every decoded array would be
    mapped afresh (reading a dataset in the same process measured 2x slower)."""
    try:
        import ctypes

        libc = ctypes.CDLL(None)
        mallopt, trim = libc.mallopt, libc.malloc_trim
    except (OSError, AttributeError):  # not glibc
        yield
        return
    m_trim, m_mmap = -1, -3  # M_TRIM_THRESHOLD, M_MMAP_THRESHOLD
    mallopt(m_mmap, 1 << 30)
    mallopt(m_trim, 1 << 30)
    try:
        yield
    finally:
        mallopt(m_trim, 64 << 20)
        mallopt(m_mmap, 32 << 20)
        trim(0)


def _in_process(tasks: list[ShardTask]) -> Iterator[ShardResult]:
    import cv2

    threads = cv2.getNumThreads()
    _limit_threads()
    try:
        with _malloc_keeps_memory():
            for t in tasks:
                yield run_shard(t)
    finally:
        cv2.setNumThreads(threads)


@contextmanager
def process_pool(workers: int) -> Iterator[Any]:
    """A pool of `workers` spawned processes, started now: each imports what a shard task needs
    while the build process goes on (checking, planning); shut down on leaving."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    # Spawned, not forked: a fork copies OpenCV's and the progress bar's threads' locks.
    ctx = multiprocessing.get_context("spawn")
    with _worker_env():
        pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx,
                                   initializer=_pool_worker_init, initargs=(os.getpid(),))
        for _ in range(workers):  # a process is spawned per submit while none is idle
            pool.submit(int)
    try:
        yield pool
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _pool_results(pool: Any, tasks: list[ShardTask]) -> Iterator[ShardResult]:
    """Submits the tasks now; results as they finish."""
    from concurrent.futures import as_completed, wait

    futures = [pool.submit(run_shard, t) for t in tasks]

    def results() -> Iterator[ShardResult]:
        try:
            for fut in as_completed(futures):
                yield fut.result()
        finally:  # the tasks not started are dropped; those running finish before a new plan
            for fut in futures:
                fut.cancel()
            wait(futures)

    return results()


#: How long to wait for a Dask scheduler given by address.
CONNECT_TIMEOUT = "10s"


@contextmanager
def dask_client(scheduler: str, workers: int) -> Iterator[Any]:
    """A Dask client: on a LocalCluster of `workers` processes ('local') or a scheduler address."""
    import logging

    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise VtsError("--scheduler needs dask.distributed (pip install 'vtsbench[cluster]')"
                       ) from None
    cluster = None
    try:
        if scheduler == "local":
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   dashboard_address=None, silence_logs=logging.ERROR)
            client = Client(cluster)
        else:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT)
    except (OSError, TimeoutError, ValueError) as e:
        if cluster is not None:
            cluster.close()
        raise VtsError(f"cannot reach the Dask scheduler at {scheduler} ({e})") from None
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _dask(tasks: list[ShardTask], client: Any) -> Iterator[ShardResult]:
    """Submits the tasks now; results as they finish."""
    from distributed import as_completed

    futures = [client.submit(run_shard, t, key=f"vtsbench-{t.kind}-{t.k}-{t.fingerprint[:16]}",
                             pure=False) for t in tasks]

    def results() -> Iterator[ShardResult]:
        try:
            for fut in as_completed(futures):
                yield fut.result()
        finally:
            client.cancel([f for f in futures if not f.done()])

    return results()


def run_tasks(tasks: list[ShardTask], opts: BuildOptions, client: Any = None,
              pool: Any = None) -> Iterator[ShardResult]:
    """Shard results as they finish: on a Dask client, in a process pool, or in this process.

    Workers get the tasks largest first (their order changes no byte): the longest tasks do not
    come last, when the other workers would have nothing left to do. In this process they run
    in plan order.
    """
    if not tasks:
        return iter(())
    largest_first = sorted(tasks, key=lambda t: -t.n_frames)
    if client is not None:
        return _dask(largest_first, client)
    if pool is not None:
        return _pool_results(pool, largest_first)
    if opts.workers > 1 and len(tasks) > 1:
        return _temporary_pool(largest_first, min(opts.workers, len(tasks)))
    return _in_process(tasks)


def _temporary_pool(tasks: list[ShardTask], workers: int) -> Iterator[ShardResult]:
    with process_pool(workers) as pool:
        results = _pool_results(pool, tasks)
        try:
            yield from results
        finally:
            results.close()


# -- the partial folder ---------------------------------------------------------------------


def partial_path(out: Path) -> Path:
    """The hidden folder a build writes into: `.OUT.partial` beside OUT."""
    return out.with_name(f".{out.name}.partial")


def lock_path(out: Path) -> Path:
    """`.OUT.lock` beside OUT: the lock of every build writing OUT (an empty file, kept)."""
    return out.with_name(f".{out.name}.lock")


@contextmanager
def locked_stage(out: Path) -> Iterator[Path]:
    """Create or reuse the partial folder, holding a lock so two builds never share it."""
    stage = partial_path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    # The lock lives beside OUT, not in the partial folder: it is held from before the existence
    # check (build re-runs check_out under it) through the final rename, and a second build
    # cannot take it while the first removes its build state and renames the folder. The holder
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
            raise VtsError("another build is writing this dataset (its lock is held)",
                           out) from None
        (stage / WORK).mkdir(parents=True, exist_ok=True)
        yield stage
    finally:
        if held:
            path.unlink(missing_ok=True)
        fh.close()


def remove_stale(stage: Path, plan: Plan) -> None:
    """Delete shard files and markers the plan has no place for (and the arrays it has none
    for), and left-over temporaries."""
    for kind in KINDS:
        lay = plan.layouts[kind]
        group = stage / "data" / f"{kind}.zarr"
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


# -- the build ------------------------------------------------------------------------------


def _progress(enabled: bool) -> Any:
    from contextlib import nullcontext

    if not enabled:
        return nullcontext(None)
    from ..progress import LineProgress, is_terminal

    if not is_terminal():  # a log or a pipe: lines, since a live bar shows nothing until the end
        return LineProgress()
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TaskProgressColumn,
        TimeRemainingColumn,
    )

    return Progress("[progress.description]{task.description}", BarColumn(),
                    MofNCompleteColumn(), TaskProgressColumn(), TimeRemainingColumn(),
                    console=Console(stderr=True))


def _check_options(opts: BuildOptions) -> None:
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
        raise VtsError(f"--version must be a semantic version such as 1.0.0, got "
                       f"{opts.version!r}")


def _semver(text: str) -> bool:
    import re

    return re.fullmatch(r"(0|[1-9]\d*)\.(0|[1-9]\d*)\.(0|[1-9]\d*)(-[0-9A-Za-z.-]+)?"
                        r"(\+[0-9A-Za-z.-]+)?", text) is not None


def _session_resolution(manifest: Manifest, sessions: set[str]) -> tuple[int, int]:
    """The frame size of a build without a calibration: that of its sessions, which must all
    have the same (a dataset has one)."""
    sizes: dict[tuple[int, int], str] = {}
    for sid in sorted(sessions):
        sizes.setdefault(tuple(manifest.session(sid).resolution), sid)
    if len(sizes) > 1:
        (a, sa), (b, sb) = list(sizes.items())[:2]
        raise VtsError(f"sessions {sa} ({a[0]}x{a[1]}) and {sb} ({b[0]}x{b[1]}) differ in frame "
                       "size; a dataset has one: build them apart")
    if not sizes:  # nothing to build: the plan says so
        return (1, 1)
    return next(iter(sizes))


def _load_checked_calibration(path: Path, manifest: Manifest, plan_sessions: set[str]) -> Any:
    """The calibration, checked against the sensor and resolution of every used session."""
    from ..depth.calibration import load_calibration

    cal = None
    for sid in sorted(plan_sessions):
        ses = manifest.session(sid)
        try:
            cal = load_calibration(path, sensor=ses.sensor, resolution=ses.resolution)
        except VtsError as e:
            raise VtsError(f"session {sid}: {e}") from None
    return cal if cal is not None else load_calibration(path)


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
    from .schema import INFO_PATH

    if not out.is_dir() or (any(out.iterdir()) and not (out / INFO_PATH).is_file()):
        raise VtsError("exists and is not a vtsbench dataset (no meta/info.json); --overwrite "
                       "replaces only datasets: remove it yourself or choose another OUT", out)


def build(recordings: str | Path, out: str | Path, opts: BuildOptions | None = None,
          log: Callable[[str], None] | None = None) -> BuildResult:
    """Build the dataset of a recordings folder into OUT (atomic: complete or absent)."""
    from ..recordings.manifest import load_manifest

    opts = opts or BuildOptions()
    say = log or (lambda _msg: None)
    t0 = time.perf_counter()
    _check_options(opts)
    root, out = Path(recordings).resolve(), Path(out).resolve()
    check_out(root, out, opts.overwrite)
    with ExitStack() as stack:
        # the workers start (and import) while this process reads the manifest, checks the
        # recordings and plans: 0.4 s sooner at work than when started after the manifest
        pool = (stack.enter_context(process_pool(opts.workers))
                if opts.workers > 1 and not opts.scheduler else None)
        manifest = load_manifest(root)
        cal_path = resolve_calibration(root, opts.calibration) if opts.depth else None
        bad, warnings = screen_entries(root, manifest, opts.frames, max(2, opts.workers),
                                       opts.progress)
        used = {e.session for e in manifest.entries if e.kind != "press" and e.id not in bad}
        if cal_path is not None:
            cal = _load_checked_calibration(cal_path, manifest, used)
            cal_sha, res, scale = sha256_file(cal_path), cal.resolution, cal.mm_per_px
        else:  # --no-depth
            cal, cal_sha, res, scale = None, "", _session_resolution(manifest, used), None
        level = opts.compression_level
        from .store import samples_per_shard

        sps = {k: samples_per_shard(res, opts.frames if k == "slip" else None,
                                    int(opts.shard_mb * 2**20)) for k in KINDS}
        if bad and not opts.skip_bad:
            raise _bad_error(bad)
        client = (stack.enter_context(dask_client(opts.scheduler, opts.workers))
                  if opts.scheduler else None)
        stage = stack.enter_context(locked_stage(out))
        check_out(root, out, opts.overwrite)  # again under the lock: another build may have
        # finished OUT between the first check and taking the lock
        kept, built, first = 0, 0, True
        previews: dict[str, Any] = {}
        while True:
            plan = make_plan(root, manifest, bad, frames=opts.frames, resolution=res,
                             mm_per_px=scale, samples_per_shard=sps, level=level,
                             arrays=ARRAYS if opts.depth else RGB_ONLY)
            if not plan.samples:
                raise VtsError("nothing to build: no usable static or sequence entries "
                               "(calibration presses are not samples)", root)
            splits = _splits(plan, opts.seed)  # leaks fail the build before the long part
            _given_splits(splits, plan, opts)
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

            late, written = _run(todo, tasks, opts, client, pool, meanwhile, previews)
            built += written
            if not late:
                break
            if not opts.skip_bad:
                raise _bad_error(late)
            bad.update(late)  # plan again without them; shards before them stay valid
            previews.clear()  # the preview rows move with the plan
        result = finish(stage, out, plan, splits, split_sha, tasks, previews,
                        manifest=manifest, root=root, cal=cal, cal_sha=cal_sha,
                        cal_path=cal_path, opts=opts)
    shards = {k: plan.layouts[k].n_shards for k in KINDS}
    return BuildResult(
        out=out, samples={k: plan.layouts[k].n for k in KINDS},
        frames={k: plan.layouts[k].n * (plan.layouts[k].frames or 1) for k in KINDS},
        shards=shards, shards_built=built, shards_kept=kept, skipped=dict(sorted(bad.items())),
        splits=[s.name for s in splits.splits], splits_skipped=dict(splits.skipped),
        bytes_on_disk=result, seconds=time.perf_counter() - t0, warnings=warnings)


def _bad_error(bad: dict[str, str]) -> VtsError:
    eid = sorted(bad)[0]
    more = (f" (and {len(bad) - 1} more bad entries)" if len(bad) > 1 else "")
    return VtsError(f"bad recording {eid}: {bad[eid]}{more}; fix it or pass --skip-bad to "
                    "leave it out")


def _given_splits(report: Any, plan: Plan, opts: BuildOptions) -> None:
    """Add the splits a user gives (--holdout-objects, --split-file), leak-checked."""
    from .given_splits import check_given, given_objects_split, read_object_list, read_split_file

    given = []
    if opts.holdout_objects is not None:
        src = str(opts.holdout_objects)
        given.append((given_objects_split(plan.samples, read_object_list(opts.holdout_objects),
                                          seed=opts.seed, source=src), src))
    given += [(read_split_file(f), str(f)) for f in opts.split_files]
    for sp, src in given:
        if report.get(sp.name) is not None or any(g.name == sp.name for g in report.splits):
            raise VtsError(f"two splits named {sp.name!r}", src)
        check_given(sp, plan.samples, src)
        report.splits.append(sp)


def _splits(plan: Plan, seed: int) -> Any:
    """The split files of the plan's samples, leak-checked: a leak is a build error."""
    from .splits import leak_check, make_splits

    res = plan.layouts["static"].frame
    report = make_splits(plan.samples, seed=seed, resolution=res)
    for sp in report.splits:
        leaks = leak_check(sp, plan.samples)
        if leaks:
            raise VtsError(f"split {sp.name} leaks: {leaks[0]}"
                           + (f" (and {len(leaks) - 1} more)" if len(leaks) > 1 else ""))
    return report


def _run(todo: list[ShardTask], tasks: list[ShardTask], opts: BuildOptions,
         client: Any = None, pool: Any = None, meanwhile: Callable[[], None] | None = None,
         previews: dict[str, Any] | None = None) -> tuple[dict[str, str], int]:
    """Run the shard tasks with progress bars; returns the bad entries found while decoding
    (it stops at the first) and the number of shards written. `meanwhile` runs once the tasks
    are handed to the workers; the preview PNGs the tasks return go into `previews`."""
    late: dict[str, str] = {}
    written = 0
    with _progress(opts.progress) as bar:
        if bar is not None:
            done = [t for t in tasks if t not in todo]
            b_shards = bar.add_task("shards", total=len(tasks), completed=len(done))
            b_frames = bar.add_task("frames", total=sum(t.n_frames for t in tasks),
                                    completed=sum(t.n_frames for t in done))
        results = run_tasks(todo, opts, client, pool)
        try:
            if meanwhile is not None:
                meanwhile()
            for r in results:
                if r.bad:  # stop: the rows after it move, so later shards are planned again
                    late.update(r.bad)
                    break
                written += 1
                if previews is not None:
                    previews.setdefault(r.kind, {}).update(r.previews)
                if bar is not None:
                    bar.advance(b_shards)
                    bar.advance(b_frames, r.frames)
        finally:
            close = getattr(results, "close", None)
            if close is not None:
                close()
    return late, written


# -- finishing: metadata, index, splits, card, report, checksums, rename -----------------------


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
    return rel.startswith(("data/", "index/", "meta/splits/"))


def build_params(manifest: Manifest, root: Path, cal_path: Path | None, opts: BuildOptions,
                 solver_note: str) -> dict[str, Any]:
    """The parameters recorded in info.json: what made the bytes, nothing about how it ran.
    Without depth (--no-depth) the depth, contact, calibration and solver are null."""
    from .depthmaps import CONTACT_PARAMS
    from .store import DEPTH_MAX_MM, DEPTH_MIN_MM, DEPTH_SCALE_MM

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
        "depth": {"dtype": "int16", "scale_mm": DEPTH_SCALE_MM,
                  "clipped_to_mm": [DEPTH_MIN_MM, DEPTH_MAX_MM], "method": solver_note}
        if depth else None,
        "contact": {"method": "colour distance of the calibration's blurred difference to its "
                              "background, cleaned by vtsbench.depth.mask.clean_mask",
                    "params": CONTACT_PARAMS} if depth else None,
        "versions": _versions(),
    }


def write_plan_files(stage: Path, plan: Plan, splits: Any) -> dict[str, str]:
    """The files that depend on the plan alone (zarr metadata, index, split files), written
    while the shard tasks run; returns the splits' sha256."""
    from .index import write_index
    from .splits import write_splits
    from .store import write_metadata

    for kind in KINDS:
        write_metadata(stage / "data" / f"{kind}.zarr", plan.layouts[kind])
        write_index(stage / "index" / f"{kind}.parquet", kind, plan.metas[kind],
                    plan.extras.get(kind))
    split_dir = stage / "meta" / "splits"
    names = {sp.name for sp in splits.splits}
    if split_dir.is_dir():
        for p in split_dir.glob("*.json"):
            if p.stem not in names:
                p.unlink()
    return write_splits(split_dir, splits.splits)


def finish(stage: Path, out: Path, plan: Plan, splits: Any, split_sha: dict[str, str],
           tasks: list[ShardTask], previews: dict[str, Any], *, manifest: Manifest,
           root: Path, cal: Any, cal_sha: str, cal_path: Path | None,
           opts: BuildOptions) -> dict[str, int]:
    """Write everything but the shards and the plan files, checksum it, and rename the stage
    to OUT."""
    from .card import write_card, write_preview
    from .schema import Calibration, Counts, DatasetInfo, ZarrSettings, dataset_checksum
    from .store import write_file

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
    (stage / "meta").mkdir(exist_ok=True)
    write_file(stage / "meta" / "build_report.json",
               (json.dumps(report, indent=1) + "\n").encode())
    write_card(stage, info, plan)
    info.files = {**content, **hash_files(
        stage, lambda rel: not _checksummed(rel) and rel != "meta/info.json")}
    write_file(stage / "meta" / "info.json", info.to_json().encode())
    sizes: dict[str, int] = {}
    for p in stage.rglob("*"):
        rel = p.relative_to(stage).as_posix()
        if p.is_file() and not rel.startswith(f"{WORK}/"):
            top = rel.split("/")[0] if "/" in rel else "."
            sizes[top] = sizes.get(top, 0) + p.stat().st_size
    shutil.rmtree(stage / WORK)
    if out.exists():  # --overwrite of a dataset (check_out): swap, then delete the old one
        import secrets

        old = out.with_name(f".{out.name}.old-{secrets.token_hex(6)}")  # a name of its own only
        os.replace(out, old)
        os.replace(stage, out)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(stage, out)
    return dict(sorted(sizes.items()))
