"""`vtsbench check`: validate a recordings folder and list every problem, not just the first."""

from __future__ import annotations

import math
from collections import Counter, defaultdict
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import VtsError
from ..labels import direction_class
from .manifest import MANIFEST_NAME, Entry, Manifest, read_manifest_doc, schema_errors
from .media import Probe, folder_frames, inspect_frame, media_kind, probe


@dataclass
class CheckReport:
    """Problems (make the check fail) and warnings (worth knowing, not wrong)."""

    problems: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    n_entries: int = 0
    n_frames: int = 0

    @property
    def ok(self) -> bool:
        return not self.problems


@dataclass
class _Media:
    """Outcome of opening one source file or folder."""

    probe: Probe | None = None
    error: str | None = None
    bad_frames: dict[int, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    #: frame index -> size (H, W) read, for the image frames decoded (every one with deep)
    sizes: dict[int, tuple[int, int]] = field(default_factory=dict)
    files: list[Path] = field(default_factory=list)  # an image folder's frames


def check_folder(folder: str | Path, deep: bool = False, workers: int = 2,
                 decode: bool = True, labels: Path | None = None,
                 progress: bool = False) -> CheckReport:
    """Check a recordings folder: schema, references, media, frame ranges, sizes and labels.

    decode=False (what `vtsbench build` screens with): PNG frames are sized from their headers
    instead of decoded, since the build decodes them anyway and reports a frame that does not
    decode; other images and the video frames are decoded as without it. progress: lines on
    stderr while the media are opened, when stderr is not a terminal."""
    folder = Path(folder)
    report = CheckReport()
    try:
        mpath, doc = read_manifest_doc(folder)
    except VtsError as e:
        report.problems.append(str(e))
        return report
    errs = schema_errors(doc)
    if errs:
        report.problems += [f"{mpath}: {e}" for e in errs]
        return report
    m = Manifest.from_dict(doc)
    report.n_entries = len(m.entries)
    _check_ids(m, report)
    media = _open_media(folder, m, deep, workers, decode, progress)
    report.warnings += [n for med in media.values() for n in med.notes]
    _check_sessions(folder, m, media, report)
    for e in m.entries:
        _check_entry(folder, m, e, media, report)
    if labels is not None:
        _check_label_file(m, Path(labels), report)
    return report


def _check_label_file(m: Manifest, labels: Path, report: CheckReport) -> None:
    """A problem for every row of a labels CSV that matches no entry (its path compared with
    the end of each entry's source path, its frame range with the entry's frames)."""
    from .labels_file import entry_frames, read_labels, row_matches

    try:
        rows = read_labels(labels)
    except VtsError as e:
        report.problems.append(str(e))
        return
    srcs = []
    for e in m.entries:
        parts = e.source.path.replace("\\", "/").split("/")
        srcs.append(([("/".join(parts[i:])) for i in range(len(parts))], entry_frames(e)))
    for row in rows:
        if not any(row_matches(row, rel, *fr) for tails, fr in srcs for rel in tails):
            rng = "" if row.start is None else f" frames {row.start}-{row.stop}"
            report.problems.append(f"{labels}: row {row.line} ({row.path}{rng}) matches no "
                                   "entry")


def _check_ids(m: Manifest, report: CheckReport) -> None:
    groups = (("session", [s.id for s in m.sessions]), ("entry", [e.id for e in m.entries]))
    for name, ids in groups:
        for i, n in Counter(ids).items():
            if n > 1:
                report.problems.append(f"{MANIFEST_NAME}: {name} id '{i}' is used {n} times")


def _frames_needed(m: Manifest) -> dict[str, set[int]]:
    """Per source path, the frame indices worth decoding to prove a range is readable."""
    need: dict[str, set[int]] = defaultdict(set)
    for e in m.entries:
        s = e.source
        if e.kind == "sequence":
            need[s.path].add(s.start or 0)
            if s.stop is not None:
                need[s.path].add(s.stop - 1)
        else:
            need[s.path].add(s.frame or 0)
    for ses in m.sessions:
        if ses.background:
            need[ses.background].add(ses.background_frame or 0)
    return need


def _open_media(folder: Path, m: Manifest, deep: bool, workers: int,
                decode: bool = True, progress: bool = False) -> dict[str, _Media]:
    """Probe every referenced source once (in threads: OpenCV releases the GIL)."""
    from ..progress import LineProgress, is_terminal

    need = _frames_needed(m)

    def one(rel: str) -> tuple[str, _Media]:
        path = folder / rel
        out = _Media()
        try:
            out.probe = probe(path, decode)
        except VtsError as e:
            out.error = str(e).removeprefix(f"{path}: ")
            return rel, out
        if out.probe.kind == "video":
            out.probe, out.bad_frames = _video_frames(path, out.probe, sorted(need[rel]), deep)
        elif decode:  # sizes, and what decoding does to a 16-bit or EXIF-oriented frame
            try:
                out.files = [path] if out.probe.kind == "image" else folder_frames(path)
            except VtsError as e:
                out.error = str(e)
                return rel, out
            every = range(len(out.files))
            _inspect_frames(out, every if deep else sorted({0, *need[rel]} & set(every)))
        return rel, out

    lines = LineProgress() if progress and not is_terminal() else None
    task = None if lines is None else lines.add_task("checking sources", total=len(need))
    out: dict[str, _Media] = {}
    with ThreadPoolExecutor(max_workers=max(1, workers)) as pool:
        for rel, media in pool.map(one, sorted(need)):
            out[rel] = media
            if lines is not None and task is not None:
                lines.advance(task)
    return out


def _inspect_frames(out: _Media, indices: Sequence[int]) -> None:
    """Decode these frames of an image or image folder: their sizes, the ones that do not
    decode, and one warning per kind of note (16-bit, EXIF) naming the first frame and how many
    more have it."""
    noted: dict[str, list[Path]] = {}
    for i in indices:
        f = out.files[i]
        try:
            size, notes = inspect_frame(f)
        except VtsError as e:
            out.bad_frames[i] = str(e)
            continue
        if size is None:
            out.bad_frames[i] = f"{f.name}: cannot decode image"
            continue
        out.sizes[i] = size
        for n in notes:
            noted.setdefault(n, []).append(f)
    out.notes = [f"{fs[0]}: {n}" + (f" (and {len(fs) - 1} more frame(s) in {fs[0].parent})"
                                    if len(fs) > 1 else "") for n, fs in noted.items()]


def _video_frames(path: Path, pr: Probe, frames: list[int], deep: bool
                  ) -> tuple[Probe, dict[int, str]]:
    """Check that the needed frames decode; with deep, decode all and count them exactly."""
    from .media import _cv2
    from .quiet import quiet_decoding

    cv2 = _cv2()
    bad: dict[int, str] = {}
    with quiet_decoding():
        cap = cv2.VideoCapture(str(path))
        try:
            if deep:
                n = 0
                while cap.grab():
                    n += 1
                return Probe(pr.kind, n, pr.height, pr.width), bad
            for i in frames:
                if i >= pr.n_frames:
                    continue  # reported as a range problem
                cap.set(cv2.CAP_PROP_POS_FRAMES, i)
                ok, frame = cap.read()
                if not ok or frame is None:
                    bad[i] = "cannot decode frame"
        finally:
            cap.release()
    return pr, bad


def _check_sessions(folder: Path, m: Manifest, media: dict[str, _Media],
                    report: CheckReport) -> None:
    for s in m.sessions:
        where = f"session {s.id}"
        if s.mm_per_px is None:
            report.warnings.append(f"{where}: mm_per_px unknown (depth in mm needs the scale)")
        if s.background is None:
            report.warnings.append(f"{where}: no background frame (calibration needs one, "
                                   "or estimates it)")
            continue
        info = media[s.background]
        if info.error:
            report.problems.append(f"{where}: background {s.background}: {info.error}")
        elif (info.probe.height, info.probe.width) != s.resolution:
            report.problems.append(
                f"{where}: background {s.background}: wrong resolution "
                f"{info.probe.height}x{info.probe.width}, session says "
                f"{s.resolution[0]}x{s.resolution[1]}")


def _check_entry(folder: Path, m: Manifest, e: Entry, media: dict[str, _Media],
                 report: CheckReport) -> None:
    src = e.source
    where = f"{e.id}: {src.path}"
    problems = report.problems
    try:
        ses = m.session(e.session)
    except KeyError:
        problems.append(f"{e.id}: unknown session '{e.session}'")
        ses = None
    info = media[src.path]
    if info.error:
        problems.append(f"{where}: {info.error}")
    else:
        pr = info.probe
        if e.kind == "sequence":
            if src.frame is not None:
                problems.append(f"{where}: a sequence takes start/stop, not 'frame'")
            start, stop = src.start or 0, pr.n_frames if src.stop is None else src.stop
            if pr.kind == "image":
                problems.append(f"{where}: a sequence needs a video or an image folder")
            elif stop <= start:
                problems.append(f"{where}: empty frame range [{start}, {stop})")
            elif stop > pr.n_frames:
                problems.append(f"{where}: frame range [{start}, {stop}) past the end "
                                f"({pr.n_frames} frames)")
            else:
                report.n_frames += stop - start
        else:
            if src.start is not None or src.stop is not None:
                problems.append(f"{where}: a {e.kind} entry takes 'frame', not start/stop")
            idx = src.frame or 0
            if idx >= pr.n_frames:
                problems.append(f"{where}: frame {idx} past the end ({pr.n_frames} frames)")
            else:
                report.n_frames += 1
        used = _frames_used(e, pr)
        for i, msg in sorted(info.bad_frames.items()):
            if pr.kind == "video" or i in used:
                problems.append(f"{where}: frame {i}: {msg}")
        sized = [(i, info.sizes[i]) for i in used if i in info.sizes]
        h, w = sized[0][1] if sized else (pr.height, pr.width)
        odd = next(((i, s) for i, s in sized if s != (h, w)), None)
        if odd is not None:
            problems.append(f"{where}: frames of two sizes: frame {sized[0][0]} is {h}x{w}, "
                            f"frame {odd[0]} ({info.files[odd[0]].name}) is "
                            f"{odd[1][0]}x{odd[1][1]}")
        if ses is not None and (h, w) != ses.resolution:
            problems.append(f"{where}: wrong resolution {h}x{w}, session "
                            f"{ses.id} says {ses.resolution[0]}x{ses.resolution[1]}")
    _check_labels(e, ses, where, report)
    if e.truth is not None and not (folder / e.truth).is_file():
        problems.append(f"{e.id}: {e.truth}: truth file not found")


def _frames_used(e: Entry, pr: Probe) -> range:
    """The frame indices of its source an entry reads."""
    src = e.source
    if e.kind == "sequence":
        return range(src.start or 0, pr.n_frames if src.stop is None else src.stop)
    return range(src.frame or 0, (src.frame or 0) + 1)


def _check_labels(e: Entry, ses, where: str, report: CheckReport) -> None:
    lab, problems = e.labels, report.problems
    if lab.direction is not None:
        if e.kind != "sequence":
            problems.append(f"{where}: direction {lab.direction} on a {e.kind} entry "
                            "(only sequences slip)")
        elif lab.state != "slip":
            problems.append(f"{where}: direction {lab.direction} on a non-slip entry "
                            f"(state {lab.state or 'unknown'})")
        elif lab.motion_mm is not None:
            k = direction_class(*lab.motion_mm, min_mm=0.0)
            if k != lab.direction:
                problems.append(f"{where}: direction {lab.direction} disagrees with motion_mm "
                                f"{list(lab.motion_mm)} (class {k})")
    if lab.state is not None and e.kind != "sequence" and lab.state != "static":
        problems.append(f"{where}: state '{lab.state}' on a single-frame {e.kind} entry")
    for name, v in (("motion_mm", lab.motion_mm), ("contact_px", lab.contact_px)):
        if v is not None and not all(math.isfinite(c) for c in v):
            problems.append(f"{where}: {name} is not finite")
        elif name == "contact_px" and v is not None and ses is not None:
            h, w = ses.resolution  # [x, y] in pixels, y down the rows; the edges included
            if not (0 <= v[0] <= w and 0 <= v[1] <= h):
                problems.append(f"{where}: contact_px [{v[0]:.6g}, {v[1]:.6g}] outside the "
                                f"frame (x in 0..{w}, y in 0..{h})")
    if e.kind == "press":
        if e.ball_radius_mm is None:
            problems.append(f"{where}: press without a ball radius (ball_radius_mm)")
        elif lab.press_depth_mm is not None and lab.press_depth_mm >= e.ball_radius_mm:
            problems.append(f"{where}: press depth {lab.press_depth_mm} mm not below the ball "
                            f"radius {e.ball_radius_mm} mm")
    if e.circle is not None and ses is not None:
        h, w = ses.resolution
        if not (0 <= e.circle.x < w and 0 <= e.circle.y < h):
            problems.append(f"{where}: circle centre ({e.circle.x}, {e.circle.y}) outside the "
                            f"{h}x{w} frame")
        if e.ball_radius_mm is not None and ses.mm_per_px is not None:
            r_ball = e.ball_radius_mm / max(ses.mm_per_px)
            if e.circle.r >= r_ball:
                report.warnings.append(f"{where}: circle radius {e.circle.r:.1f} px not below "
                                       f"the ball radius {r_ball:.1f} px (it will be clamped)")


def is_media(path: Path) -> bool:
    """True when the path is a source vtsbench can read."""
    try:
        media_kind(path)
    except VtsError:
        return False
    return True
