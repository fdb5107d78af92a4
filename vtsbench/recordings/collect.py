"""`vtsbench collect`: record a camera or a video file into a recordings folder.

The first `background_frames` frames of the stream show the untouched sensor: their per-pixel
median becomes the session's background (unless a background file is given) and they are never
cut into entries. The frames after them become, by `kind`:

- sequence: fixed-length windows of `window` frames every `stride` frames, written as one image
  folder per take; each window is an entry whose source is a [start, stop) range of that folder;
- static: every `every`-th frame, one PNG per entry;
- press: frames that differ from the background (contact), at most one every `every` frames.

Labels come from an optional motion log (see `vtsbench.recordings.motionlog`): frame i of the
capture is at log time i / fps + log_offset_s; a window's stage displacement between its first and
last frame is mapped through the session's mount into the image frame and labelled with
`label_motion`.

Nothing half-written is ever referenced: frames are written into a hidden staging folder that
takes its final name only when the recording is complete, and the manifest is written last,
atomically.
"""

from __future__ import annotations

import contextlib
import math
import re
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..atomic import check_replaceable, staged_dir
from ..errors import VtsError
from ..labels import PRESS_THRESHOLD_MM, SLIP_THRESHOLD_MM, Thresholds, label_motion
from . import media
from .manifest import (
    MANIFEST_NAME,
    Entry,
    Labels,
    Manifest,
    Mount,
    Session,
    Source,
    load_manifest,
    save_manifest,
)
from .motionlog import MotionLog, read_motion_log

MODES: tuple[str, ...] = ("sequence", "static", "press")
ID_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")  # the schema's id pattern
BACKGROUND_NAME = "background.png"
FRAME_NAME = "{:06d}.png"  # frame files are named by their index in the capture

DEFAULT_BACKGROUND_FRAMES = 10
DEFAULT_WINDOW = 8
DEFAULT_EVERY = 10
#: A pixel shows contact when its colour differs from the background by more than this many
#: gray levels (0-255, largest channel) after a CONTACT_BLUR_PX box blur of the difference.
CONTACT_LEVEL = 10.0
#: A frame shows contact when at least this fraction of its pixels do.
CONTACT_AREA = 0.001
CONTACT_BLUR_PX = 5


@dataclass(frozen=True)
class CollectOptions:
    """What `vtsbench collect` records and how; None means "from the session, or the default"."""

    source: str
    session: str = "s0"
    sensor: str | None = None
    mm_per_px: float | None = None
    fps: float | None = None
    mount_rotation_deg: float | None = None
    mount_mirror: bool | None = None
    background_frames: int = DEFAULT_BACKGROUND_FRAMES
    background: Path | None = None
    kind: str = "sequence"
    window: int = DEFAULT_WINDOW
    stride: int | None = None
    every: int = DEFAULT_EVERY
    ball_radius_mm: float | None = None
    contact_level: float = CONTACT_LEVEL
    contact_area: float = CONTACT_AREA
    object: str | None = None
    take: str | None = None
    max_frames: int | None = None
    motion_log: Path | None = None
    log_offset_s: float = 0.0
    slip_threshold_mm: float | None = None  # default labels.SLIP_THRESHOLD_MM
    press_threshold_mm: float | None = None  # default labels.PRESS_THRESHOLD_MM
    append: bool = False
    overwrite: bool = False


@dataclass
class CollectResult:
    """What one run added."""

    out: Path
    manifest: Manifest
    session: str
    take: str
    entries: list[Entry]
    frames_read: int
    new_session: bool
    stopped: bool = False  # a camera recording ended by Ctrl-C


# -- the capture -----------------------------------------------------------------------------


def _cv2():
    import cv2

    return cv2


# -- labels and contact ----------------------------------------------------------------------


def _mm(v: float) -> float:
    """Round a length for the manifest (1e-9 mm) and drop the sign of zero."""
    return round(float(v), 9) + 0.0


def frame_time(index: int, fps: float, offset_s: float) -> float:
    """Log time (s) of capture frame `index`: index / fps + offset."""
    return index / fps + offset_s


def window_labels(log: MotionLog | None, first: int, last: int, fps: float, offset_s: float,
                  mount: Mount, thresholds: Thresholds) -> Labels:
    """Labels of the window whose first and last capture frames are `first` and `last`.

    The stage displacement between the two frame times is mapped through the mount into the
    image frame and labelled with `label_motion`; the press depth is z at the last frame (0 when
    the indenter is off the gel). Unknown without a log or when either time is outside it.
    """
    if log is None:
        return Labels()
    a = log.at(frame_time(first, fps, offset_s))
    b = log.at(frame_time(last, fps, offset_s))
    if a is None or b is None:
        return Labels()
    dx, dy = mount.to_image(b[0] - a[0], b[1] - a[1])
    lab = label_motion(dx, dy, b[2] - a[2], thresholds)
    return Labels(state=lab.state, direction=lab.direction,
                  motion_mm=(_mm(lab.motion_mm[0]), _mm(lab.motion_mm[1])),
                  press_depth_mm=_mm(max(0.0, b[2])))


def frame_labels(log: MotionLog | None, index: int, fps: float, offset_s: float) -> Labels:
    """Labels of a single captured frame: the press depth (z, 0 when off the gel) if logged."""
    p = None if log is None else log.at(frame_time(index, fps, offset_s))
    return Labels() if p is None else Labels(press_depth_mm=_mm(max(0.0, p[2])))


def contact_fraction(frame: np.ndarray, background: np.ndarray,
                     level: float = CONTACT_LEVEL, blur_px: int = CONTACT_BLUR_PX) -> float:
    """Fraction of pixels whose blurred colour difference to the background exceeds `level`.

    The signed difference is box-blurred before taking its magnitude, so that sensor noise
    averages out while an imprint (a smooth change over many pixels) stays.
    """
    d = frame.astype(np.float32) - background.astype(np.float32)
    if blur_px > 1:
        d = _cv2().blur(d, (blur_px, blur_px))
    return float((np.abs(d).max(axis=2) > level).mean())


def median_background(frames: list[np.ndarray]) -> np.ndarray:
    """Per-pixel median of no-contact frames as RGB uint8."""
    return np.clip(np.rint(np.median(np.stack(frames), axis=0)), 0, 255).astype(np.uint8)


# -- planning --------------------------------------------------------------------------------


def _check_options(o: CollectOptions) -> None:
    if o.kind not in MODES:
        raise VtsError(f"unknown --kind {o.kind!r} (one of {', '.join(MODES)})")
    if o.append and o.overwrite:
        raise VtsError("--append and --overwrite exclude each other")
    for name, value in (("--session", o.session), ("--take", o.take)):
        if value is not None and not ID_RE.match(value):
            raise VtsError(f"{name} {value!r}: use letters, digits, '.', '_' and '-' (starting "
                           "with a letter or digit)")
    if o.object is not None and not o.object.strip():
        raise VtsError("--object must not be empty")
    if o.sensor is not None and not o.sensor.strip():
        raise VtsError("--sensor must not be empty")
    if o.kind == "press" and o.ball_radius_mm is None:
        raise VtsError("--kind press needs --ball-radius-mm (the indenter's radius in mm)")
    if o.kind != "press" and o.ball_radius_mm is not None:
        raise VtsError("--ball-radius-mm applies to --kind press only")
    positive = (("--mm-per-px", o.mm_per_px), ("--fps", o.fps),
                ("--ball-radius-mm", o.ball_radius_mm),
                ("--slip-threshold-mm", o.slip_threshold_mm),
                ("--press-threshold-mm", o.press_threshold_mm))
    for name, value in positive:
        if value is not None and not (math.isfinite(value) and value > 0):
            raise VtsError(f"{name} must be a positive number, got {value}")
    if o.window < 2:
        raise VtsError(f"--window must be at least 2 frames, got {o.window}")
    for name, value in (("--stride", o.stride), ("--every", o.every),
                        ("--max-frames", o.max_frames)):
        if value is not None and value < 1:
            raise VtsError(f"{name} must be at least 1, got {value}")
    if o.background_frames < 0:
        raise VtsError(f"--background-frames must be >= 0, got {o.background_frames}")
    if not 0 < o.contact_area <= 1:
        raise VtsError(f"--contact-area must be in (0, 1], got {o.contact_area}")
    if not math.isfinite(o.log_offset_s):
        raise VtsError("--log-offset must be finite")


def _check_session_options(o: CollectOptions, s: Session, where: Path) -> None:
    """Options given for an existing session must agree with what it records."""
    def clash(what: str, given: object, has: object) -> VtsError:
        return VtsError(f"session {s.id} has {what} {has}, not {given} (leave the option out, "
                        "or record into a new --session)", where)

    if o.sensor is not None and o.sensor != s.sensor:
        raise clash("sensor", o.sensor, s.sensor)
    if o.mm_per_px is not None and s.mm_per_px != (o.mm_per_px, o.mm_per_px):
        raise clash("mm_per_px", o.mm_per_px, s.mm_per_px)
    if o.mount_rotation_deg is not None and o.mount_rotation_deg != s.mount.rotation_deg:
        raise clash("mount rotation", o.mount_rotation_deg, s.mount.rotation_deg)
    if o.mount_mirror is not None and o.mount_mirror != s.mount.mirror:
        raise clash("mount mirror", o.mount_mirror, s.mount.mirror)
    if o.background is not None:
        raise VtsError(f"session {s.id} already has its background; --background applies to a "
                       "new session only", where)


def _next_take(manifest: Manifest | None, session: str, session_dir: Path) -> str:
    """The smallest free take number (001, 002, ...) in the session, on disk and in the manifest."""
    used: set[str] = set()
    if manifest is not None:
        used = {e.take for e in manifest.entries if e.session == session and e.take}
    used_numbers = {int(t) for t in used if t.isdigit()}
    n = 1
    while (n in used_numbers or f"{n:03d}" in used or (session_dir / f"{n:03d}").exists()):
        n += 1
    return f"{n:03d}"


@dataclass
class _Plan:
    """Everything the recording loop needs, decided before the first frame is read."""

    opts: CollectOptions
    session: str
    take: str
    fps: float
    mount: Mount
    thresholds: Thresholds
    log: MotionLog | None
    resolution: tuple[int, int] | None  # expected (h, w), when known beforehand
    resolution_of: str  # where that expectation comes from, for messages
    background: np.ndarray | None  # known before reading (file or existing session)
    need_background: bool  # compute it from the first frames


@dataclass
class _Recording:
    entries: list[Entry] = field(default_factory=list)
    frames_read: int = 0
    background: np.ndarray | None = None
    resolution: tuple[int, int] | None = None
    stopped: bool = False


# -- recording -------------------------------------------------------------------------------


def _progress(enabled: bool):
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
    )

    from ..progress import progress_bar

    if not enabled:
        return Progress(disable=True)
    return progress_bar(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                        TimeElapsedColumn(), transient=False)


def _record(cap: media.Capture, take_dir: Path, plan: _Plan, progress: bool) -> _Recording:
    """Read the stream, write frames into take_dir (a staging folder) and build the entries."""
    o = plan.opts
    rec = _Recording(background=plan.background, resolution=plan.resolution)
    n_bg = o.background_frames
    stride = o.stride or o.window
    rel_dir = f"{plan.session}/{plan.take}"
    bg_frames: list[np.ndarray] = []
    keep: set[str] = set()  # single-frame files referenced by an entry
    seq_end = n_bg  # sequence frames [n_bg, seq_end) of the capture are inside some window
    last_kept: int | None = None
    max_contact = 0.0
    take_dir.mkdir(parents=True, exist_ok=True)

    def add(kind: str, source: Source, labels: Labels, first: int, **extra) -> None:
        meta = {"capture_frame": first, **extra.pop("meta", {})}
        rec.entries.append(Entry(
            id=f"{plan.session}-{plan.take}-{len(rec.entries):04d}", kind=kind,
            session=plan.session, source=source, object=o.object, take=plan.take, labels=labels,
            meta=meta, **extra))

    total = o.max_frames if cap.n_frames is None else min(cap.n_frames, o.max_frames or
                                                          cap.n_frames)
    with _progress(progress) as bar:
        task = bar.add_task(f"reading {cap.name}", total=total)
        try:
            while o.max_frames is None or rec.frames_read < o.max_frames:
                frame = cap.read()
                if frame is None:
                    break
                i = rec.frames_read
                rec.frames_read += 1
                bar.advance(task)
                shape = (int(frame.shape[0]), int(frame.shape[1]))
                if rec.resolution is None:
                    rec.resolution = shape
                elif shape != rec.resolution:
                    what = plan.resolution_of if i == 0 else "the frames before"
                    raise VtsError(f"frame {i} is {shape[0]}x{shape[1]} pixels, unlike "
                                   f"{what} ({rec.resolution[0]}x{rec.resolution[1]})", cap.name)
                if i < n_bg:
                    if plan.need_background:
                        bg_frames.append(frame)
                    continue
                if rec.background is None and plan.need_background:
                    rec.background = median_background(bg_frames)
                    bg_frames.clear()
                name = FRAME_NAME.format(i)
                j = i - n_bg  # index among the frames after the background
                if o.kind == "sequence":
                    media.write_png(take_dir / name, frame)
                    start = j - o.window + 1
                    if start >= 0 and start % stride == 0:
                        first = n_bg + start
                        seq_end = i + 1
                        add("sequence", Source(rel_dir, start=start, stop=j + 1),
                            window_labels(plan.log, first, i, plan.fps, o.log_offset_s,
                                          plan.mount, plan.thresholds), first)
                elif o.kind == "static":
                    if j % o.every == 0:
                        media.write_png(take_dir / name, frame)
                        keep.add(name)
                        add("static", Source(f"{rel_dir}/{name}"),
                            frame_labels(plan.log, i, plan.fps, o.log_offset_s), i)
                else:
                    assert rec.background is not None
                    frac = contact_fraction(frame, rec.background, o.contact_level)
                    max_contact = max(max_contact, frac)
                    if frac >= o.contact_area and (last_kept is None or i - last_kept >= o.every):
                        media.write_png(take_dir / name, frame)
                        keep.add(name)
                        last_kept = i
                        add("press", Source(f"{rel_dir}/{name}"),
                            frame_labels(plan.log, i, plan.fps, o.log_offset_s), i,
                            ball_radius_mm=o.ball_radius_mm,
                            meta={"contact_fraction": round(frac, 6)})
        except KeyboardInterrupt:
            if not cap.is_camera:
                raise
            rec.stopped = True  # Ctrl-C ends a live recording; complete entries are kept
    keep.update(FRAME_NAME.format(k) for k in range(n_bg, seq_end))
    for p in take_dir.iterdir():  # frames past the last window, or cut short by Ctrl-C
        if p.name not in keep:
            p.unlink()
    if rec.frames_read == 0:
        raise VtsError("no frame could be read", cap.name)
    if rec.background is None and plan.need_background:
        raise VtsError(f"only {rec.frames_read} frame(s) read, all of them background "
                       f"(--background-frames {n_bg})", cap.name)
    if not rec.entries:
        after = max(0, rec.frames_read - n_bg)
        if o.kind == "sequence":
            why = f"too few for one window of {o.window} frames"
        elif o.kind == "press":
            why = (f"none shows contact (largest contact fraction {max_contact:.4f} < "
                   f"--contact-area {o.contact_area})")
        else:
            why = "none to keep"
        raise VtsError(f"{rec.frames_read} frame(s) read, {after} after {n_bg} background "
                       f"frame(s): {why}", cap.name)
    return rec


@contextlib.contextmanager
def _opened(source: str) -> Iterator[media.Capture]:
    cap = media.Capture(source)
    try:
        yield cap
    finally:
        cap.close()


def collect(out: str | Path, opts: CollectOptions, progress: bool = True) -> CollectResult:
    """Record `opts.source` into the recordings folder `out`; returns what was added."""
    out = Path(out)
    _check_options(opts)
    thresholds = Thresholds(
        SLIP_THRESHOLD_MM if opts.slip_threshold_mm is None else opts.slip_threshold_mm,
        PRESS_THRESHOLD_MM if opts.press_threshold_mm is None else opts.press_threshold_mm)
    log = read_motion_log(opts.motion_log) if opts.motion_log is not None else None

    manifest: Manifest | None = None
    if out.exists():
        if opts.append:
            manifest = load_manifest(out)
        elif not opts.overwrite:
            raise VtsError("already exists (use --append to add to it, or --overwrite to "
                           "replace it)", out)
        else:  # before recording anything: a folder vtsbench did not write is never replaced
            check_replaceable(out, True, MANIFEST_NAME)
    where = out / MANIFEST_NAME
    session: Session | None = None
    if manifest is not None:
        session = next((s for s in manifest.sessions if s.id == opts.session), None)
        if session is not None:
            _check_session_options(opts, session, where)

    bg_file = None
    if opts.background is not None:
        bg_file = media.read_image(Path(opts.background))
    background: np.ndarray | None = bg_file
    resolution: tuple[int, int] | None = None
    resolution_of = ""
    if session is not None:
        resolution, resolution_of = session.resolution, f"session {session.id}'s resolution"
        if opts.kind == "press" and session.background:
            background = media.read_frame(out / session.background, session.background_frame or 0)
    elif bg_file is not None:
        resolution = (int(bg_file.shape[0]), int(bg_file.shape[1]))
        resolution_of = f"the background {opts.background}"
    need_background = background is None and (session is None or opts.kind == "press")
    if need_background and opts.background_frames < 1:
        raise VtsError("no background: give --background FILE or --background-frames N >= 1")

    session_dir = out / opts.session
    take = opts.take or _next_take(manifest, opts.session, session_dir)
    if manifest is not None:
        if any(e.session == opts.session and e.take == take for e in manifest.entries):
            raise VtsError(f"session {opts.session} already has a take {take} (choose another "
                           "--take, or leave it out for the next free number)", where)
        if (session_dir / take).exists():
            raise VtsError("already exists (choose another --take)", session_dir / take)

    mount = session.mount if session is not None else Mount(opts.mount_rotation_deg or 0.0,
                                                            bool(opts.mount_mirror))
    with _opened(opts.source) as cap:
        fps = opts.fps or cap.fps or (session.fps if session is not None else None)
        if fps is None:
            raise VtsError("frame rate unknown (the source reports none): pass --fps", cap.name)
        if session is not None and session.fps and not math.isclose(fps, session.fps,
                                                                     rel_tol=1e-6):
            raise VtsError(f"frame rate {fps:g} differs from session {session.id}'s "
                           f"{session.fps:g} (pass --fps {session.fps:g} if the capture runs at "
                           "that rate, or record into a new --session)", cap.name)
        plan = _Plan(opts, opts.session, take, fps, mount, thresholds, log, resolution,
                     resolution_of, background, need_background)

        def build(rec: _Recording) -> tuple[Manifest, Session | None]:
            new = None
            if session is None:
                assert rec.resolution is not None
                mm = None if opts.mm_per_px is None else (opts.mm_per_px, opts.mm_per_px)
                new = Session(id=opts.session, sensor=opts.sensor or "unknown",
                              resolution=rec.resolution, mm_per_px=mm, fps=fps,
                              background=f"{opts.session}/{BACKGROUND_NAME}", mount=mount)
            entries = rec.entries
            if manifest is None:
                return Manifest([new], entries, created_by="vtsbench collect"), new
            taken = {e.id for e in manifest.entries}
            clash = next((e.id for e in entries if e.id in taken), None)
            if clash is not None:
                raise VtsError(f"entry id {clash} is already used (choose another --take)", where)
            sessions = manifest.sessions + ([new] if new is not None else [])
            return replace(manifest, sessions=sessions, entries=manifest.entries + entries), new

        if manifest is None:
            with staged_dir(out, overwrite=opts.overwrite, marker=MANIFEST_NAME) as stage:
                rec = _record(cap, stage / opts.session / take, plan, progress)
                m, _ = build(rec)
                bg = rec.background if bg_file is None else bg_file
                media.write_png(stage / opts.session / BACKGROUND_NAME, bg)
                save_manifest(stage, m)
        else:
            with staged_dir(session_dir / take) as stage:
                rec = _record(cap, stage, plan, progress)
                m, new = build(rec)
            if new is not None:
                bg = rec.background if bg_file is None else bg_file
                media.write_png(session_dir / BACKGROUND_NAME, bg)  # atomic
            save_manifest(out, m)
    return CollectResult(out, m, opts.session, take, rec.entries, rec.frames_read,
                         session is None, rec.stopped)
