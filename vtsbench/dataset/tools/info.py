"""`vtsbench info`: what a built dataset holds, from info.json and the index, as rich tables.

Counts per object (static samples and slip samples per state), per slip direction and per
split part, sizes on disk per folder against the raw size (uint8 RGB + float32 depth), and
the versions and checksum that identify the dataset (a dataset built with --no-depth: uint8
RGB alone). Reads no array data. It says how the frames are stored (Zarr, or the episodes'
RGB as video with the codec and its settings) and, where the samples are views of the
episode store (format 1.3), how many episodes, the frames the samples read and those stored
once.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ...labels import DIRECTION_NAMES, STATES
from ..format.index import read_index
from ..format.info import DatasetInfo, load_info
from ..format.layout import (
    DATA_DIR,
    EPISODES,
    EPISODES_GROUP,
    EPISODES_INDEX,
    KINDS,
    VIDEOS_DIR,
    index_path,
)


@dataclass
class Summary:
    """The numbers `vtsbench info` shows."""

    info: DatasetInfo
    by_object: dict[str, dict[str, int]] = field(default_factory=dict)
    sizes: dict[str, int] = field(default_factory=dict)
    raw_bytes: int = 0


def summarise(root: str | Path) -> Summary:
    """Read info.json and the indexes of a dataset (no arrays): a folder, or any URL
    `vtsbench.load` takes."""
    from ..read.remote import local_path

    path = local_path(root)
    if path is None:
        return _summarise_remote(str(root))
    return _summarise(path)


def _summarise(root: Path) -> Summary:
    """summarise of a dataset folder."""
    info = load_info(root)
    tables = {}
    for kind in KINDS:
        path = root / index_path(kind)
        if path.is_file():
            tables[kind] = read_index(path, kind, columns=_columns(kind))
    if info.episodes is not None:
        tables[EPISODES] = read_index(root / EPISODES_INDEX, EPISODES, columns=["object"])
    sizes: dict[str, int] = {}
    for p in root.rglob("*"):
        if p.is_file():
            _add_size(sizes, p.relative_to(root).parts, p.stat().st_size)
    return _summary(info, tables, sizes)


def _summarise_remote(url: str) -> Summary:
    """summarise of a dataset at a URL: sizes of the files info.json lists."""
    from ..read.location import Location
    from ..read.remote import remote_info, remote_sizes

    loc = Location(url)
    info = remote_info(loc)
    tables = {kind: loc.checked(index_path(kind), functools.partial(
        read_index, kind=kind, columns=_columns(kind))) for kind in KINDS}
    if info.episodes is not None:
        tables[EPISODES] = loc.checked(EPISODES_INDEX, functools.partial(
            read_index, kind=EPISODES, columns=["object"]))
    sizes: dict[str, int] = {}
    for rel, size in remote_sizes(loc, info).items():
        _add_size(sizes, tuple(rel.split("/")), size)
    return _summary(info, tables, sizes)


def _columns(kind: str) -> list[str]:
    return ["object", "state"] if kind == "slip" else ["object"]


def _add_size(sizes: dict[str, int], rel: tuple[str, ...], size: int) -> None:
    """Add a file's size to its group: data/<kind>.zarr, or the top folder."""
    top = "/".join(rel[:2]) if rel[0] == DATA_DIR and len(rel) > 2 else rel[0]
    sizes[top] = sizes.get(top, 0) + size


def _summary(info: DatasetInfo, tables: dict[str, Any], sizes: dict[str, int]) -> Summary:
    """Counts per object and state from the index tables; raw size from the shapes."""
    by_object: dict[str, dict[str, int]] = {o: {} for o in info.objects}
    for kind, t in tables.items():
        d = t.to_pydict()
        for i, obj in enumerate(d["object"]):
            key = (kind if kind in ("static", EPISODES)
                   else f"slip:{d['state'][i] or 'unknown'}")
            row = by_object.setdefault(obj, {})
            row[key] = row.get(key, 0) + 1
    raw = 0
    for kind, shapes in info.shapes.items():
        if info.views and kind in KINDS:
            continue  # format 1.3: their frames are the episode store's, counted once
        raw += _prod(shapes["rgb"]) + (4 * _prod(shapes["depth"]) if "depth" in shapes else 0)
    return Summary(info, by_object, dict(sorted(sizes.items())), raw)


def _prod(shape: Any) -> int:
    out = 1
    for v in shape:
        out *= int(v)
    return out


def human(n: float) -> str:
    """Bytes as B, KB, MB, GB (powers of 1000)."""
    for unit in ("B", "KB", "MB", "GB"):
        if abs(n) < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000
    return f"{n:.1f} TB"


def views_line(s: Summary) -> str:
    """Format 1.3: the samples are views of the episodes, their frames stored once."""
    info, ep = s.info, s.info.episodes
    assert ep is not None
    n_static, n_slip = info.counts.static.samples, info.counts.slip.samples
    t = info.frames_per_sequence
    def size(group: str) -> str:
        n = s.sizes.get(group)
        return f"{group}, {human(n)} ({n} bytes)" if n is not None else group

    where = size(EPISODES_GROUP) if ep.video is None else \
        f"{size(VIDEOS_DIR)} (RGB) and {size(EPISODES_GROUP)}"
    return (f"samples: views of {ep.episodes} episodes (frames stored once): {n_static} static "
            f"frames and {n_slip} slip sequences of {t} read {n_static + n_slip * t} frames "
            f"from the {ep.frames} stored in {where}")


def render(s: Summary, console: Any) -> None:
    """Print the summary as rich tables."""
    from rich.markup import escape
    from rich.table import Table

    from ..build.card import storage_line

    info = s.info
    cal = info.calibration
    depth = (f"calibration {cal.sensor + ' / ' + cal.method if cal else 'none'}, solver "
             f"{info.build.get('solver', '?')}" if info.has_depth
             else "rgb only: no depth or contact (built with --no-depth)")
    if info.episodes is not None and info.created_by == "vtsbench.create":  # no build of it
        depth = "rgb, depth and contact" if info.has_depth else "rgb only: no depth or contact"
    console.print(f"[bold]{escape(info.name)}[/] " + escape(
                  f"{info.dataset_version} (format {info.format_version}, "
                  f"vtsbench {info.vtsbench_version}); {info.resolution[0]}x"
                  f"{info.resolution[1]} frames, T = {info.frames_per_sequence}; {depth}"),
                  highlight=False)
    console.print(f"dataset_sha256 {info.dataset_sha256}", highlight=False)
    console.print(escape(f"frames stored as {storage_line(info)}"), highlight=False)
    ep = info.episodes
    if ep is not None:
        console.print(f"episodes {ep.episodes}, {ep.frames} frames ({ep.dropped_frames} dropped"
                      f"); frames per state: " + ", ".join(f"{k} {v}" for k, v in
                                                           ep.states.items()), highlight=False)
        if info.views:
            console.print(views_line(s), highlight=False)
    t = Table(title="samples per object", title_justify="left")
    cols = ["static", *(f"slip:{x}" for x in STATES)]
    if any("slip:unknown" in row for row in s.by_object.values()):
        cols.append("slip:unknown")
    if info.episodes is not None:
        cols.append(EPISODES)
    longest = max((len(o) for o in s.by_object), default=6)
    t.add_column("object", min_width=min(longest, 40), overflow="fold")  # names never cut
    for c in ("class", *cols):  # "slip:press" headed "slip" over "press": fits 80 columns
        t.add_column(c.replace(":", "\n"), justify="right", overflow="fold")
    tot = dict.fromkeys(cols, 0)
    for obj, row in sorted(s.by_object.items()):
        t.add_row(escape(obj), str(info.objects.index(obj)) if obj in info.objects else "?",
                  *(str(row.get(c, 0)) for c in cols))
        for c in cols:
            tot[c] += row.get(c, 0)
    t.add_row("[bold]total[/]", "", *(f"[bold]{v}[/]" for v in tot.values()))
    console.print(t)
    d = Table(title="slip directions (state slip)", title_justify="left")
    for c, just in (("class", "right"), ("direction", "left"), ("samples", "right")):
        d.add_column(c, justify=just)  # one row a class: fits any terminal, never cut
    dirs = info.counts.slip.directions
    for k, name in enumerate(DIRECTION_NAMES):
        d.add_row(str(k), name, str(dirs.get(str(k), 0)))
    d.add_row("", "unknown", str(dirs.get("unknown", 0)))
    console.print(d)
    sp = Table(title="splits", title_justify="left")
    for c in ("split", "parts"):
        sp.add_column(c, overflow="fold")
    for name, parts in info.counts.splits.items():
        sp.add_row(escape(name), ", ".join(f"{p} {n}" for p, n in parts.items()))
    console.print(sp)
    sz = Table(title="on disk", title_justify="left")
    sz.add_column("folder")
    sz.add_column("size", justify="right")
    for k, v in s.sizes.items():
        sz.add_row(k, human(v))
    total = sum(s.sizes.values())
    sz.add_row("[bold]total[/]", f"[bold]{human(total)}[/]")
    data = sum(v for k, v in s.sizes.items() if k.startswith(f"{DATA_DIR}/"))
    if s.raw_bytes:
        sz.add_row("raw arrays (uint8 RGB + float32 depth)" if info.has_depth
                   else "raw arrays (uint8 RGB)",
                   f"{human(s.raw_bytes)} (data/ is {data / s.raw_bytes:.0%} of it)")
    console.print(sz)
