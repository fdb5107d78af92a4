"""Planning a build from the manifest alone: the usable entries, their samples (windows of T
frames for sequences), rows, class indices, array layouts and the leak-checked splits."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ...errors import VtsError
from ...recordings.manifest import Entry, Manifest
from ..format.arrays import Layout
from ..format.index import extra_column_name
from ..format.layout import ARRAYS, KINDS
from ..format.records import SampleMeta
from .options import BuildOptions

if TYPE_CHECKING:
    from ..splits.schemes import SplitReport

CALIBRATION_NAME = "calibration.safetensors"


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
    from ...recordings.check import check_folder

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
    from ...recordings.media import probe

    start = e.source.start or 0
    stop = (e.source.stop if e.source.stop is not None
            else probe(root / e.source.path, decode=False).n_frames)
    return max(0, stop - start)


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


def session_resolution(manifest: Manifest, sessions: set[str]) -> tuple[int, int]:
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


def load_checked_calibration(path: Path, manifest: Manifest, plan_sessions: set[str]) -> Any:
    """The calibration, checked against the sensor and resolution of every used session."""
    from ...depth.calibration import load_calibration

    cal = None
    for sid in sorted(plan_sessions):
        ses = manifest.session(sid)
        try:
            cal = load_calibration(path, sensor=ses.sensor, resolution=ses.resolution)
        except VtsError as e:
            raise VtsError(f"session {sid}: {e}") from None
    return cal if cal is not None else load_calibration(path)


def bad_error(bad: dict[str, str]) -> VtsError:
    eid = sorted(bad)[0]
    more = (f" (and {len(bad) - 1} more bad entries)" if len(bad) > 1 else "")
    return VtsError(f"bad recording {eid}: {bad[eid]}{more}; fix it or pass --skip-bad to "
                    "leave it out")


def add_given_splits(report: SplitReport, plan: Plan, opts: BuildOptions) -> None:
    """Add the splits a user gives (--holdout-objects, --split-file), leak-checked."""
    from ..splits.given import check_given, given_objects_split, read_object_list, read_split_file

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


def plan_splits(plan: Plan, seed: int) -> SplitReport:
    """The split files of the plan's samples, leak-checked: a leak is a build error."""
    from ..splits.leaks import leak_check
    from ..splits.schemes import make_splits

    res = plan.layouts["static"].frame
    report = make_splits(plan.samples, seed=seed, resolution=res)
    for sp in report.splits:
        leaks = leak_check(sp, plan.samples)
        if leaks:
            raise VtsError(f"split {sp.name} leaks: {leaks[0]}"
                           + (f" (and {len(leaks) - 1} more)" if len(leaks) > 1 else ""))
    return report


def frame_and_calibration(cal_path: Path | None, manifest: Manifest, bad: dict[str, str]
                          ) -> tuple[Any, str, tuple[int, int], tuple[float, float] | None]:
    """The calibration (checked against every used session), its sha256, the frame size and
    the scale in mm per pixel; without a calibration (--no-depth) the sessions' frame size."""
    from ..format.provenance import sha256_file

    used = {e.session for e in manifest.entries if e.kind != "press" and e.id not in bad}
    if cal_path is None:
        return None, "", session_resolution(manifest, used), None
    cal = load_checked_calibration(cal_path, manifest, used)
    return cal, sha256_file(cal_path), cal.resolution, cal.mm_per_px
