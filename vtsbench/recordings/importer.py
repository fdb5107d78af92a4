"""`vtsbench manifest`: describe a folder of existing files from a file-name pattern, in place."""

from __future__ import annotations

import math
import os
import re
import sys
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

from ..errors import VtsError
from .manifest import MANIFEST_NAME, Circle, Entry, Labels, Manifest, Session, Source, save_manifest
from .media import media_kind, probe

FIELD_RE = re.compile(r"\{([A-Za-z_][A-Za-z0-9_]*)(?::([a-z]))?\}")
LABEL_FIELDS = ("object", "take", "session", "state", "direction")
CIRCLE_COLUMNS = {
    "file": ("file", "img_names", "image", "name", "filename"),
    "x": ("x", "center_x", "cx"),
    "y": ("y", "center_y", "cy"),
    "r": ("r", "radius"),
}


@dataclass(frozen=True)
class ManifestOptions:
    """What `vtsbench manifest` knows beyond the file names."""

    pattern: str
    kind: str | None = None
    sensor: str = "unknown"
    session: str = "s0"
    mm_per_px: float | None = None
    fps: float | None = None
    background: str | None = None
    ball_radius_mm: float | None = None
    circles: Path | None = None
    window: int | None = None
    stride: int | None = None
    force: bool = False
    out: Path | None = None  # where recordings.json goes (default: the folder itself)
    labels: Path | None = None  # CSV of labels per file, folder or frame range
    markers: tuple[str, ...] = ()  # FILE:FIELD=VALUE, a label from a marker file's presence
    progress: bool = False  # lines on stderr while probing the files, when not a terminal


def compile_pattern(pattern: str) -> re.Pattern[str]:
    """Turn '{object}_{take:d}.mov' into a regex; fields are greedy and never cross '/'."""
    out, pos, seen = "", 0, set()
    for m in FIELD_RE.finditer(pattern):
        name, typ = m.group(1), m.group(2)
        if name in seen:
            raise VtsError(f"pattern {pattern!r}: field '{{{name}}}' appears twice")
        if typ not in (None, "d"):
            raise VtsError(f"pattern {pattern!r}: unknown field type ':{typ}' (only ':d')")
        seen.add(name)
        out += re.escape(pattern[pos:m.start()])
        out += f"(?P<{name}>\\d+)" if typ == "d" else f"(?P<{name}>[^/]+)"
        pos = m.end()
    out += re.escape(pattern[pos:].rstrip("/"))
    if "{" in pattern[pos:] or "}" in pattern[pos:]:
        raise VtsError(f"pattern {pattern!r}: unbalanced braces")
    return re.compile(out + r"\Z")


def match_files(folder: Path, pattern: str) -> list[tuple[str, dict[str, str]]]:
    """Relative paths under folder matching the pattern (folders if it ends with '/'), sorted."""
    rx = compile_pattern(pattern)
    want_dirs = pattern.endswith("/")
    found = []
    for p in sorted(folder.rglob("*")):
        if p.name.startswith(".") or p.is_dir() != want_dirs or p.name == MANIFEST_NAME:
            continue
        rel = p.relative_to(folder).as_posix()
        m = rx.match(rel)
        if m:
            found.append((rel, m.groupdict()))
    return found


def safe_id(text: str, fallback: str = "entry") -> str:
    """text in the manifest's id alphabet: each run of other characters ('/' too) becomes
    '-', and the ends are trimmed ('4.700mm/12' -> '4.700mm-12')."""
    return re.sub(r"[^A-Za-z0-9._-]+", "-", text.strip("/")).strip("-._") or fallback


def first_repeat(ids: list[str]) -> str | None:
    """The first id that appears a second time, or None (one pass)."""
    seen: set[str] = set()
    for i in ids:
        if i in seen:
            return i
        seen.add(i)
    return None


def _entry_id(rel: str) -> str:
    stem = rel.rsplit(".", 1)[0] if "." in rel.rsplit("/", 1)[-1] else rel
    return safe_id(stem)


def _labels(fields: dict[str, str], rel: str) -> Labels:
    state = fields.get("state")
    if state is not None and state not in ("static", "press", "slip"):
        raise VtsError(f"state '{state}' from the file name is not static, press or slip", rel)
    direction = fields.get("direction")
    if direction is not None:
        if not direction.isdigit() or not 0 <= int(direction) <= 7:
            raise VtsError(f"direction '{direction}' from the file name is not 0..7", rel)
        direction = int(direction)
    return Labels(state=state, direction=direction)


def read_circles(path: Path) -> dict[str, Circle]:
    """Read a circles CSV into {file name: Circle}; one-line errors naming the row."""
    from ..jsonio import read_csv

    rows = read_csv(path, "circles CSV")
    header = [h.lower() for h in rows[0]] if rows else []
    cols = {}
    for key, names in CIRCLE_COLUMNS.items():
        hit = [h for h in header if h in names]
        if not hit:
            raise VtsError(f"no '{key}' column (accepted: {', '.join(names)}); "
                           f"found {', '.join(header) or 'no header'}", path)
        cols[key] = header.index(hit[0])
    out: dict[str, Circle] = {}
    for i, cells in enumerate(rows[1:], start=2):
        row = cells + [""] * (len(header) - len(cells))
        name = row[cols["file"]].strip()
        try:
            x, y, r = (float(row[cols[k]]) for k in ("x", "y", "r"))
        except (TypeError, ValueError):
            raise VtsError(f"row {i}: x, y and r must be numbers", path) from None
        if not all(math.isfinite(v) for v in (x, y, r)):
            raise VtsError(f"row {i}: x, y and r must be finite numbers", path)
        if not name or r <= 0:
            raise VtsError(f"row {i}: needs a file name and a positive radius", path)
        if name in out:
            raise VtsError(f"row {i}: '{name}' listed twice", path)
        out[name] = Circle(x, y, r)
    return out


def _parts(path: str) -> list[str]:
    return [p for p in path.replace("\\", "/").split("/") if p not in ("", ".")]


def _names(name: str) -> set[str]:
    """A file name and its stem: a row may give either ('0000', '0000.png', 'a.01.png')."""
    return {name, name.rsplit(".", 1)[0]}


def _shared_tail(key: str, rel: str) -> int:
    """How many trailing path components a CSV row's file and a matched file share: 0 when
    their names differ (compared whole or without the extension), else 1 plus the folders
    above that agree."""
    kp, rp = _parts(key), _parts(rel)
    if not kp or not rp:
        return 0
    if not _names(kp[-1]) & _names(rp[-1]):
        return 0
    n = 1
    while n < min(len(kp), len(rp)) and kp[-1 - n] == rp[-1 - n]:
        n += 1
    return n


def assign_circles(circles: dict[str, Circle], rels: list[str], csv: Path | None
                   ) -> dict[str, str]:
    """{file: CSV row's file}: each row goes to the file whose path it shares most trailing
    components with (a row's path may come from another machine: '/qt_images/0000.png'
    matches '0000.png'; 'a/3/gelsight.png' matches that file among many 'gelsight.png'). A row
    that fits several files alike, or two rows whose best file is the same, is a one-line
    error naming them: a circle is never guessed. Files no row picks get none."""
    by_name: dict[str, list[str]] = {}
    for rel in rels:
        for n in _names((_parts(rel) or [""])[-1]):
            by_name.setdefault(n, []).append(rel)
    out: dict[str, str] = {}
    for key in circles:
        near = {r for n in _names((_parts(key) or [""])[-1]) for r in by_name.get(n, [])}
        fits = [(d, rel) for rel in sorted(near) if (d := _shared_tail(key, rel))]
        if not fits:
            continue
        top = max(d for d, _ in fits)
        best = [rel for d, rel in fits if d == top]
        if len(best) > 1:
            raise VtsError(f"row '{key}' fits {best[0]} and {best[1]} alike: give the path "
                           "relative to the folder", csv)
        if best[0] in out:
            raise VtsError(f"rows '{out[best[0]]}' and '{key}' both fit {best[0]}", csv)
        out[best[0]] = key
    return out


def _stderr_warning(msg: str) -> None:
    print(f"warning: {msg}", file=sys.stderr)


def build_pattern_manifest(folder: Path, opts: ManifestOptions,
                           warn: Callable[[str], None] | None = None) -> Manifest:
    """A manifest for the files under folder that match opts.pattern (files stay in place).

    With --window, a video or image folder shorter than the window makes no sequence: it is
    left out with a warning (`warn`, one line each, then the count), not an error."""
    folder = Path(folder)
    say = warn or (lambda _msg: None)
    if not folder.is_dir():
        raise VtsError("not a folder", folder)
    if opts.kind not in (None, "static", "sequence", "press"):
        raise VtsError(f"unknown kind '{opts.kind}' (static, sequence or press)")
    if opts.kind == "press" and opts.ball_radius_mm is None:
        raise VtsError("presses need --ball-radius-mm")
    if opts.circles is not None and opts.kind != "press":
        raise VtsError("--circles applies to presses: add --kind press")
    home = Path(opts.out) if opts.out is not None else folder

    def ref(rel: str) -> str:  # a path relative to the manifest's folder
        return Path(os.path.relpath(folder / rel, home)).as_posix()

    bg_files = {opts.background} if opts.background and "{" not in opts.background else set()
    matches = [(r, f) for r, f in match_files(folder, opts.pattern) if r not in bg_files]
    if not matches:
        raise VtsError(f"no file matches the pattern {opts.pattern!r}", folder)
    circles = read_circles(opts.circles) if opts.circles else {}
    placed = assign_circles(circles, [r for r, _ in matches], opts.circles) if circles else {}
    used = set(placed.values())
    from .labels_file import Marker, apply_labels, apply_values, read_labels

    markers = [Marker.parse(t) for t in opts.markers]
    label_rows = read_labels(opts.labels) if opts.labels is not None else []
    stride = opts.stride or opts.window
    entries: list[Entry] = []
    rels: list[str] = []
    short: list[str] = []
    session_probe: dict[str, tuple[int, int, float | None]] = {}
    from ..progress import LineProgress, is_terminal

    lines = LineProgress() if opts.progress and not is_terminal() else None
    task = lines.add_task("reading files", total=len(matches)) if lines is not None else 0
    for rel, fields in matches:
        path = folder / rel
        pr = probe(path)
        if lines is not None:
            lines.advance(task)
        kind = opts.kind or ("static" if pr.kind == "image" else "sequence")
        if kind == "sequence" and pr.kind == "image":
            raise VtsError("a sequence needs a video or an image folder", path)
        if kind == "sequence" and opts.window and pr.n_frames < opts.window:
            short.append(rel)
            say(f"{rel}: {pr.n_frames} frames, fewer than --window {opts.window}: left out")
            continue
        ses = fields.get("session", opts.session)
        if ses not in session_probe:
            session_probe[ses] = (pr.height, pr.width, _video_fps(path) if pr.kind == "video"
                                  else None)
        src = ref(rel)
        base = Entry(id=_entry_id(rel), kind=kind, session=ses, source=Source(src),
                     object=fields.get("object"), take=fields.get("take"),
                     labels=_labels(fields, rel),
                     meta={k: v for k, v in fields.items() if k not in LABEL_FIELDS})
        if kind == "press":
            base = replace(base, ball_radius_mm=opts.ball_radius_mm,
                           circle=circles[placed[rel]] if rel in placed else None,
                           source=Source(src, frame=None if pr.kind == "image" else 0))
        elif kind == "static" and pr.kind != "image":
            base = replace(base, source=Source(src, frame=0))
        marked = {m.field: m.value for m in markers if m.applies(folder, rel)}
        if marked:
            base = apply_values(base, marked)
        n_before = len(entries)
        if kind == "sequence" and opts.window:
            for k, s in enumerate(range(0, pr.n_frames - opts.window + 1, stride)):
                entries.append(replace(base, id=f"{base.id}-w{k:03d}",
                                       source=Source(src, start=s, stop=s + opts.window)))
        elif kind == "static" and pr.kind != "image" and opts.stride:
            # a static frame every --stride frames of a video or image folder
            for f in range(0, pr.n_frames, opts.stride):
                entries.append(replace(base, id=f"{base.id}-f{f:05d}",
                                       source=Source(src, frame=f)))
        else:
            entries.append(base)
        rels += [rel] * (len(entries) - n_before)
    if short:
        say(f"left out {len(short)} of {len(matches)} matched files, shorter than --window "
            f"{opts.window}")
        if not entries:
            raise VtsError(f"every matched file is shorter than --window {opts.window}", folder)
    if label_rows:
        entries, stray = apply_labels(list(zip(rels, entries, strict=True)), label_rows)
        for row in stray[:20]:
            say(f"{opts.labels}: row {row.line} ({row.path}) matches no entry")
        if stray:
            say(f"{len(stray)} of {len(label_rows)} label rows match no entry "
                "(`vtsbench check --labels` lists them)")
    unused = sorted(set(circles) - used)
    if unused:
        raise VtsError(f"{len(unused)} circle row(s) match no file of the pattern, first "
                       f"'{unused[0]}'", opts.circles)
    dup = first_repeat([e.id for e in entries])
    if dup is not None:
        raise VtsError(f"two files map to the entry id '{dup}'; add a field to the pattern")
    sessions = []
    for sid, (h, w, vfps) in session_probe.items():
        bg = opts.background.replace("{session}", sid) if opts.background else None
        if bg is not None and not (folder / bg).exists():
            raise VtsError("background file not found", folder / bg)
        mm = None if opts.mm_per_px is None else (opts.mm_per_px, opts.mm_per_px)
        sessions.append(Session(id=sid, sensor=opts.sensor, resolution=(h, w), mm_per_px=mm,
                                fps=opts.fps or vfps, background=None if bg is None else ref(bg)))
    return Manifest(sessions=sessions, entries=entries,
                    created_by=f"vtsbench manifest --pattern {opts.pattern}")


def _video_fps(path: Path) -> float | None:
    from .media import _cv2
    from .quiet import quiet_decoding

    cv2 = _cv2()
    with quiet_decoding():
        cap = cv2.VideoCapture(str(path))
    try:
        fps = cap.get(cv2.CAP_PROP_FPS)
    finally:
        cap.release()
    return round(float(fps), 6) if fps and fps > 0 else None


def write_pattern_manifest(folder: Path, opts: ManifestOptions,
                           warn: Callable[[str], None] | None = _stderr_warning
                           ) -> tuple[Manifest, Path]:
    """Build and write recordings.json (in opts.out or the folder); refuses to replace one
    unless opts.force. Warnings (files left out) go to `warn`: stderr by default."""
    home = Path(opts.out) if opts.out is not None else Path(folder)
    home.mkdir(parents=True, exist_ok=True)
    target = home / MANIFEST_NAME
    if target.exists() and not opts.force:
        raise VtsError("already exists (use --overwrite to replace it)", target)
    m = build_pattern_manifest(Path(folder), opts, warn)
    return m, save_manifest(home, m)


__all__ = ["ManifestOptions", "build_pattern_manifest", "compile_pattern", "first_repeat",
           "match_files", "media_kind", "read_circles", "safe_id", "write_pattern_manifest"]
