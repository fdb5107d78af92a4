"""`vtsbench check`: validate a recordings folder and list every problem, not just the first."""

from __future__ import annotations

import contextlib
import math
from collections import Counter, defaultdict
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import VtsError
from ..labels import direction_class
from .manifest import MANIFEST_NAME, Entry, Manifest, read_manifest_doc, schema_errors
from .media import Probe, folder_frames, frame_notes, media_kind, probe


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
        elif decode:  # what decoding does to a 16-bit or EXIF-oriented frame
            first = path if out.probe.kind == "image" else folder_frames(path)[0]
            with contextlib.suppress(VtsError):
                out.notes = [f"{first}: {n}" for n in frame_notes(first)]
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


def _video_frames(path: Path, pr: Probe, frames: list[int], deep: bool
                  ) -> tuple[Probe, dict[int, str]]:
    """Check that the needed frames decode; with deep, decode all and count them exactly."""
    import cv2

    bad: dict[int, str] = {}
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
        for i, msg in sorted(info.bad_frames.items()):
            problems.append(f"{where}: frame {i}: {msg}")
        if ses is not None and (pr.height, pr.width) != ses.resolution:
            problems.append(f"{where}: wrong resolution {pr.height}x{pr.width}, session "
                            f"{ses.id} says {ses.resolution[0]}x{ses.resolution[1]}")
    _check_labels(e, ses, where, report)
    if e.truth is not None and not (folder / e.truth).is_file():
        problems.append(f"{e.id}: {e.truth}: truth file not found")


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
