"""`vtsbench build --store episodes`: the build written on the public episode writer
(build/writer.py). The plan is the build's (samples, rows, labels, splits); each take (the
plan's samples of one source file or folder) becomes one episode holding the frames from its
first sample's first frame to its last sample's last, decoded with the recordings' readers and
given depth and contact with the calibration as a shard task does (build/shard.py); then every
sample is declared on its episode (`add_sample`), in plan order, so that rows, labels, ids and
split files are today's build's. Takes are decoded in a process pool with --workers > 1 and
written by this process in take order; a rerun resumes the writer and skips the saved takes.
With --video each take's RGB is stored as one video file (the writer's `video`). A lab's
splits: --holdout-objects makes given_objects over the samples (as a samples build does) and
episode_given_objects over the takes (the writer's `holdout_objects`), the same objects held
out; a --split-file of kind "episode" names takes by episode id (their source paths) and is
checked against the takes before any frame is decoded.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import VtsError
from ...recordings.manifest import Manifest
from ..format.layout import ARRAYS, KINDS, RGB_ONLY
from ..format.records import SampleMeta, SplitFile
from .options import BuildOptions, check_options
from .plan import (
    Plan,
    SampleSource,
    add_given_splits,
    bad_error,
    frame_and_calibration,
    make_plan,
    plan_splits,
    resolve_calibration,
    screen_entries,
)
from .staging import check_out, partial_path, recover
from .store import samples_per_shard

#: The frame rate of a take whose session and file give none.
DEFAULT_FPS = 25.0


@dataclass(frozen=True)
class Take:
    """One episode to write: a source and the frame range its samples cover, and the entries
    (id, start, stop) whose samples it holds."""

    path: str
    start: int
    stop: int
    object: str
    session: str
    entries: tuple[tuple[str, int, int], ...]
    #: per frame of the take: (state, direction) from the slip sample covering it
    states: tuple[str | None, ...] = ()
    directions: tuple[int | None, ...] = ()


@dataclass(frozen=True)
class TakeTask:
    """What a worker needs to decode a take and make its depth and contact (picklable)."""

    root: str
    take: Take
    frame: tuple[int, int]
    calibration: str
    calibration_sha: str
    solver: str
    depth: bool


@dataclass
class TakeFrames:
    """A decoded take: rgb (T, H, W, 3), depth (mm) and contact, or the entries it could not
    read (id -> one line)."""

    rgb: np.ndarray | None = None
    depth: np.ndarray | None = None
    contact: np.ndarray | None = None
    bad: dict[str, str] = field(default_factory=dict)


def make_takes(plan: Plan) -> list[Take]:
    """The plan's samples grouped by source, in order of first appearance (static kind first,
    as the plan's rows); one object and session a take, else a one-line error."""
    groups: dict[str, list[tuple[SampleMeta, SampleSource]]] = {}
    for kind in KINDS:
        for m, s in zip(plan.metas[kind], plan.sources[kind], strict=True):
            groups.setdefault(s.path, []).append((m, s))
    takes = []
    for path, items in groups.items():
        for what in ("object", "session"):
            vals = {getattr(m, what): s.entry_id for m, s in items}
            if len(vals) > 1:
                (a, ea), (b, eb) = list(vals.items())[:2]
                raise VtsError(f"entries {ea} and {eb} of one take ({path}) differ in {what} "
                               f"({a!r}, {b!r}): an episode has one object and one session; "
                               "build them with --store samples")
        start, stop = min(s.start for _, s in items), max(s.stop for _, s in items)
        states: list[str | None] = [None] * (stop - start)
        dirs: list[int | None] = [None] * (stop - start)
        for m, s in reversed(items):  # the first sample covering a frame labels it
            if m.kind == "slip" and m.state is not None:
                states[s.start - start:s.stop - start] = [m.state] * (s.stop - s.start)
                dirs[s.start - start:s.stop - start] = [m.direction] * (s.stop - s.start)
        entries = tuple(dict.fromkeys((s.entry_id, s.start, s.stop) for _, s in items))
        takes.append(Take(path, start, stop, items[0][0].object, items[0][0].session, entries,
                          tuple(states), tuple(dirs)))
    return takes


def decode_take(task: TakeTask) -> TakeFrames:
    """Frames of a take, and their depth and contact (shard.py's depth_and_contact: the build's
    depth bit for bit); a take that does not decode names its bad entries."""
    from ...recordings.media import read_frames
    from .shard import _calibration, depth_and_contact

    root, t = Path(task.root), task.take
    want = (t.stop - t.start, *task.frame, 3)
    try:
        rgb = read_frames(root / t.path, t.start, t.stop)
        if rgb.shape != want:
            raise VtsError(f"frames [{t.start}, {t.stop}) are {'x'.join(map(str, rgb.shape))}, "
                           f"expected {'x'.join(map(str, want))}", root / t.path)
    except Exception:  # find the entries at fault, decoding each alone
        return TakeFrames(bad=_bad_entries(root, t, want[1:]))
    out = TakeFrames(rgb=rgb)
    if task.depth:
        cal = _calibration(task.calibration, task.calibration_sha)
        out.depth, out.contact = depth_and_contact(rgb, cal, task.solver)
    return out


def _bad_entries(root: Path, t: Take, frame: tuple[int, ...]) -> dict[str, str]:
    from ...recordings.media import read_frames

    bad: dict[str, str] = {}
    for eid, a, b in t.entries:
        try:
            x = read_frames(root / t.path, a, b)
        except VtsError as e:
            prefix = f"{root}/"
            text = str(e)
            bad[eid] = text[len(prefix):] if text.startswith(prefix) else text
            continue
        except Exception as e:  # OpenCV and decoders raise their own types
            bad[eid] = f"{t.path}: cannot decode frames [{a}, {b}) ({e})"
            continue
        if x.shape[1:] != frame:
            bad[eid] = (f"{t.path}: frames [{a}, {b}) are {'x'.join(map(str, x.shape))}, "
                        f"expected {'x'.join(map(str, (b - a, *frame)))}")
    return bad or {t.entries[0][0]: f"{t.path}: frames [{t.start}, {t.stop}) do not decode "
                                    "together"}


def _decoded(tasks: list[TakeTask], pool: Any, ahead: int) -> Iterator[TakeFrames]:
    """Decoded takes in order: in this process, or `ahead` at a time in the pool."""
    if pool is None:
        for t in tasks:
            yield decode_take(t)
        return
    futures: list[Any] = []
    try:
        for i in range(len(tasks)):
            while len(futures) < ahead and i + len(futures) < len(tasks):
                futures.append(pool.submit(decode_take, tasks[i + len(futures)]))
            yield futures.pop(0).result()
    finally:
        for f in futures:
            f.cancel()


def take_fps(root: Path, manifest: Manifest, take: Take) -> float | None:
    """The frame rate of a take: its session's, else its video file's (None when unknown)."""
    fps = manifest.session(take.session).fps
    if fps:
        return float(fps)
    path = root / take.path
    if path.is_file() and path.suffix.lower() in (".avi", ".mp4", ".mkv", ".mov", ".webm"):
        import cv2

        from ...recordings.quiet import quiet_decoding

        with quiet_decoding():
            cap = cv2.VideoCapture(str(path))
        try:
            got = cap.get(cv2.CAP_PROP_FPS)
        finally:
            cap.release()
        if np.isfinite(got) and 0 < got < 1e4:
            return float(got)
    return None


def _provenance(manifest: Manifest, root: Path, cal: Any, cal_sha: str, cal_path: Path | None,
                opts: BuildOptions) -> dict[str, Any]:
    """What info.json records of the build: its parameters, as `build --store samples` does."""
    from ..format.info import Calibration
    from .finish import build_params

    params = build_params(manifest, root, cal_path, opts,
                          "" if cal is None else f"{cal.method} + {opts.solver}")
    params["store"] = "episodes"
    params.pop("versions")
    return {"created_by": "vtsbench build --store episodes",
            "calibration": None if cal is None else Calibration(cal.sensor, cal.method, cal_sha),
            "build": params}


def _progress(enabled: bool) -> Any:
    from contextlib import nullcontext

    if not enabled:
        return nullcontext(None)
    from ...progress import progress_bar

    return progress_bar(transient=False)


def build_episodes(root: Path, out: Path, opts: BuildOptions,
                   say: Callable[[str], None]) -> dict[str, Any]:
    """Build OUT from the recordings at root as episodes with the samples as views of them
    (format 1.3); returns pipeline.BuildResult's fields."""
    from ...recordings.manifest import load_manifest
    from .execute import process_pool
    from .writer import EpisodeWriter

    t0 = time.perf_counter()
    check_options(opts)
    if opts.scheduler:
        raise VtsError("--store episodes runs on this machine (--workers); --scheduler (Dask) "
                       "builds --store samples only")
    recover(out)
    check_out(root, out, opts.overwrite)
    with ExitStack() as stack:
        pool = stack.enter_context(process_pool(opts.workers)) if opts.workers > 1 else None
        manifest = load_manifest(root)
        cal_path = resolve_calibration(root, opts.calibration) if opts.depth else None
        bad, warnings = screen_entries(root, manifest, opts.frames, max(2, opts.workers),
                                       opts.progress)
        cal, cal_sha, res, scale = frame_and_calibration(cal_path, manifest, bad)
        if bad and not opts.skip_bad:
            raise bad_error(bad)
        sps = {k: samples_per_shard(res, opts.frames if k == "slip" else None,
                                    int(opts.shard_mb * 2**20)) for k in KINDS}
        arrays = ARRAYS if opts.depth else RGB_ONLY
        prov = _provenance(manifest, root, cal, cal_sha, cal_path, opts)
        episode_splits, sample_opts = _episode_split_files(opts)
        held_out = None
        if opts.holdout_objects is not None:
            from ..splits.given import read_object_list

            held_out = read_object_list(opts.holdout_objects)
        w = stack.enter_context(_closing(EpisodeWriter(
            out, fps=DEFAULT_FPS, arrays=arrays, sensor="unknown",
            name=manifest.name or root.name, calibration_sha256=cal_sha or None, resume=True,
            overwrite=opts.overwrite, dataset_version=opts.version,
            compression_level=opts.compression_level, shard_mb=opts.shard_mb, seed=opts.seed,
            frames_per_sequence=opts.frames, provenance=prov, video=opts.video,
            holdout_objects=held_out)))
        check_out(root, out, opts.overwrite)
        kept, written, first = w.episodes, 0, True
        while True:
            plan = make_plan(root, manifest, bad, frames=opts.frames, resolution=res,
                             mm_per_px=scale, samples_per_shard=sps,
                             level=opts.compression_level, arrays=arrays)
            if not plan.samples:
                raise VtsError("nothing to build: no usable static or sequence entries "
                               "(calibration presses are not samples)", root)
            splits = plan_splits(plan, opts.seed)
            fixed = {s.name for s in splits.splits}  # the writer makes them again at finish
            add_given_splits(splits, plan, sample_opts)
            takes = make_takes(plan)
            _check_episode_splits(episode_splits, takes, {s.name for s in splits.splits})
            _check_saved(w, takes, partial_path(out))
            if first and kept:
                say(f"resuming {partial_path(out).name}: {kept} of {len(takes)} takes already "
                    "saved")
            first = False
            late = _write_takes(w, takes, root, manifest, res, cal_path, cal_sha, opts, pool,
                                warnings)
            written += late[1]
            if not late[0]:
                break
            if not opts.skip_bad:
                raise bad_error(late[0])
            bad.update(late[0])
        for kind in KINDS:  # the samples, in plan order: rows, ids and labels as the plan's
            _add_samples(w, kind, plan, takes)
        for sp in [*splits.splits, *(sp for sp, _ in episode_splits)]:
            if sp.name not in fixed:
                w.add_split(sp)
        w.finish()
        made = json.loads((out / "meta" / "info.json").read_text())
    sizes: dict[str, int] = {}
    for p in out.rglob("*"):
        if p.is_file():
            rel = p.relative_to(out).as_posix()
            top = rel.split("/")[0] if "/" in rel else "."
            sizes[top] = sizes.get(top, 0) + p.stat().st_size
    lay = plan.layouts
    return {"out": out, "samples": {k: lay[k].n for k in KINDS},
            "frames": {k: lay[k].n * (lay[k].frames or 1) for k in KINDS},
            "shards": {k: 0 for k in KINDS}, "shards_built": written, "shards_kept": kept,
            "skipped": dict(sorted(bad.items())), "splits": sorted(made["splits"]),
            "splits_skipped": dict(made["build"]["splits_skipped"]),
            "bytes_on_disk": dict(sorted(sizes.items())), "seconds": time.perf_counter() - t0,
            "warnings": warnings, "takes": len(takes)}


class _closing:
    """A writer closed (lock let go, partial folder kept) when the block ends."""

    def __init__(self, w: Any) -> None:
        self.w = w

    def __enter__(self) -> Any:
        return self.w

    def __exit__(self, *exc: object) -> None:
        self.w.close()


def take_id(take: Take) -> str:
    """An episode's id: its source path (one take per path)."""
    return take.path


def _episode_split_files(opts: BuildOptions) -> tuple[list[tuple[SplitFile, str]],
                                                      BuildOptions]:
    """The --split-file files of kind "episode" (read and schema-checked, with their paths)
    and the options holding the others, which the plan checks against the samples."""
    from ..splits.episodes import EPISODE
    from ..splits.given import read_split_file

    read = [(read_split_file(f), f) for f in opts.split_files]
    episodes = [(sp, str(f)) for sp, f in read if sp.kind == EPISODE]
    rest = tuple(f for sp, f in read if sp.kind != EPISODE)
    return episodes, replace(opts, split_files=rest)


def _check_episode_splits(given: list[tuple[SplitFile, str]], takes: list[Take],
                          taken: set[str]) -> None:
    """Each given split of episodes against the takes (ids are take_id's; none in two parts;
    its disjoint rules) and the names of the other splits, one line naming its file."""
    import pyarrow as pa

    from ..splits.episodes import EPISODE, EPISODE_SCHEMES, check_episode_split
    from ..splits.given import GIVEN

    table = pa.table({"episode_id": [take_id(t) for t in takes],
                      "object": [t.object for t in takes],
                      "session": [t.session for t in takes]})
    ours = {f"{EPISODE}_{n}" for n in (*EPISODE_SCHEMES, GIVEN)}
    for sp, src in given:
        if sp.name in ours | taken:
            raise VtsError(f"two splits named {sp.name!r} (a scheme's and a given one, or two "
                           "given)", src)
        taken = taken | {sp.name}
        check_episode_split(sp, table, src)


def _check_saved(w: Any, takes: list[Take], stage: Path) -> None:
    """The saved episodes of a resumed writer are the first takes of this plan, else one line."""
    saved = w.saved_episodes
    for k, rec in enumerate(saved):
        t = takes[k] if k < len(takes) else None
        if t is None or rec["episode_id"] != take_id(t) or rec["length"] != t.stop - t.start:
            raise VtsError(f"the partial build holds episode {k} {rec['episode_id']!r} "
                           f"({rec['length']} frames), which this plan does not make there "
                           "(the recordings changed): delete it to start again", stage)


def _write_takes(w: Any, takes: list[Take], root: Path, manifest: Manifest,
                 res: tuple[int, int], cal_path: Path | None, cal_sha: str, opts: BuildOptions,
                 pool: Any, warnings: list[str]) -> tuple[dict[str, str], int]:
    """Decode and save every take not yet saved, in take order; stops at the first take that
    does not decode (its bad entries returned) and returns how many were written."""
    todo = takes[w.episodes:]
    tasks = [TakeTask(str(root), t, res, "" if cal_path is None else str(cal_path), cal_sha,
                      opts.solver, cal_path is not None) for t in todo]
    written = 0
    with _progress(opts.progress) as bar:
        if bar is not None:
            b_takes = bar.add_task("takes", total=len(takes), completed=len(takes) - len(todo))
            b_frames = bar.add_task("frames", total=sum(t.stop - t.start for t in takes),
                                    completed=sum(t.stop - t.start for t in takes[:w.episodes]))
        results = _decoded(tasks, pool, 2 * opts.workers)
        try:
            for t, got in zip(todo, results, strict=False):
                if got.bad:
                    return got.bad, written
                fps = take_fps(root, manifest, t)
                if fps is None:
                    note = (f"{t.path}: no frame rate in its session or file: timestamps at "
                            f"{DEFAULT_FPS:g} fps")
                    if note not in warnings:
                        warnings.append(note)
                w.add_episode(got.rgb, states=list(t.states), directions=list(t.directions),
                              depth=None if got.depth is None else np.nan_to_num(got.depth),
                              contact=got.contact, object=t.object, session=t.session,
                              episode_id=take_id(t), fps=fps or DEFAULT_FPS,
                              sensor=manifest.session(t.session).sensor)
                written += 1
                if bar is not None:
                    bar.advance(b_takes)
                    bar.advance(b_frames, t.stop - t.start)
        finally:
            results.close()
    return {}, written


def _add_samples(w: Any, kind: str, plan: Plan, takes: list[Take]) -> None:
    """Declare the plan's samples of a kind on their episodes, skipping those a resumed writer
    committed."""
    starts = {t.path: t.start for t in takes}
    extras = plan.extras.get(kind, {})
    done = w.sample_ids
    for i, (m, s) in enumerate(zip(plan.metas[kind], plan.sources[kind], strict=True)):
        if m.sample_id in done:
            continue
        labels: dict[str, Any] = {
            "press_depth_mm": m.press_depth_mm, "source": m.source,
            "contact_px": None if m.contact_x_px is None else (m.contact_x_px, m.contact_y_px),
            "mm_per_px": None if m.mm_per_px_x is None else (m.mm_per_px_x, m.mm_per_px_y),
            "fields": {n: v[i] for n, v in extras.items() if v[i] is not None}}
        if kind == "slip":
            labels.update(state=m.state, direction=m.direction,
                          motion_mm=None if m.motion_dx_mm is None
                          else (m.motion_dx_mm, m.motion_dy_mm))
        w.add_sample(kind, episode=s.path, start=s.start - starts[s.path],
                     sample_id=m.sample_id, **labels)

