"""The episodes in the Hugging Face copy (`vtsbench export-hf` of a dataset with episodes):
hf/episodes/, laid out as LeRobot v2.1 lays out a dataset, so a LeRobot user finds their way.

`meta/info.json` (features with dtype, shape and names; totals; fps; `data_path`; splits),
`meta/episodes.jsonl` (episode_index, tasks, length), `meta/tasks.jsonl` (a task per object),
`meta/episodes_stats.jsonl` (min, max, mean, std, count per feature and episode), and one
parquet file per episode, `data/chunk-CCC/episode_NNNNNN.parquet`, one row per frame:
`episode_index`, `frame_index`, `timestamp`, `index` (the frame's row in the frames store),
`task_index`, the labels (`state`, `direction`: ClassLabels, -1 where unknown), the frames' own
values, and the images as the samples' hub files hold them (hub_rows: rgb a lossless TIFF,
depth a 16-bit TIFF of the stored counts, contact a 1-bit PNG), under LeRobot's
`observation.images.*` names. What LeRobot has no slot for (object, session, sensor, slip
onset, the splits of episodes) is under `vtsbench` keys. No LeRobot `codebase_version` is
claimed: its loaders expect PNG or video frames and float32 timestamps.

Each episode file is written through a temporary name and marked done with its fingerprint and
its statistics, so a killed export resumes keeping the episodes already written.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import shutil
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ...atomic import replacing, write_bytes_atomic
from ...labels import DIRECTION_NAMES, STATES
from ..format.episodes import FRAME_COLUMNS
from ..format.records import part_key
from ..splits.episodes import EPISODE
from .hub_layout import (
    CHUNKS_SIZE,
    EPISODE_DATA_PATH,
    EPISODES_CONFIG,
    EPISODES_GLOB,
    EPISODES_HUB,
    EPISODES_META,
    EpisodesHub,
    HubFile,
    episode_file,
    split_name,
)
from .hub_rows import _as_type, mask_png, stored_counts, tiff
from .hub_stats import Moments, image_moments, label_stats
from .hub_write import ROW_GROUP_BYTES, done_marker, kept_marker, ordered, write_failed

if TYPE_CHECKING:
    import pyarrow as pa

    from ..read.loader import VtsDataset

#: The layout of hf/episodes/ (in info.json's and the parquet schema's `vtsbench` key).
EPISODES_HUB_VERSION = 1
#: What the subtree follows, said in its info.json instead of LeRobot's codebase_version.
LAYOUT_OF = "lerobot v2.1 meta files"
#: The dataset's arrays -> their columns, LeRobot's names for camera images.
IMAGE_KEYS = {"rgb": "observation.images.rgb", "depth": "observation.images.depth",
              "contact": "observation.images.contact"}
#: LeRobot's per-frame columns, first in every row.
LEROBOT_COLUMNS = ("episode_index", "frame_index", "timestamp", "index", "task_index")
#: How each image column is encoded (info.json features' `info`).
ENCODINGS = {"rgb": "TIFF, zstd with the horizontal predictor: the stored uint8 RGB exactly",
             "depth": "16-bit TIFF, zstd: the stored int16 depth counts' bits (view as int16, "
                      "x depth_scale_mm = mm into the gel)",
             "contact": "1-bit PNG: the contact mask (bool)"}
#: The `datasets` dtype of a frames.parquet value column's arrow type.
_DTYPES = {"bool": "bool", "int64": "int64", "double": "float64", "string": "string",
           "large_string": "string"}


def hub_columns(frames: pa.Schema) -> dict[str, str]:
    """The frames' own value columns -> their names in the hub rows: their own, or with the
    prefix `meta_` where LeRobot's columns take the name (`index`, `task_index`)."""
    taken = {*LEROBOT_COLUMNS, "state", "direction", *IMAGE_KEYS.values()}
    out = {}
    for name in frames.names[len(FRAME_COLUMNS):]:
        col = name
        while col in taken:
            col = f"meta_{col}"
        taken.add(col)
        out[name] = col
    return out


def _dtype(typ: pa.DataType) -> str:
    return _DTYPES.get(str(typ), str(typ))


def datasets_features(info: Any, frames: pa.Schema) -> dict[str, Any]:
    """The `datasets` features of an episode file's rows (as the JSON datasets writes)."""
    def value(dtype: str) -> dict[str, Any]:
        return {"dtype": dtype, "_type": "Value"}

    feats: dict[str, Any] = {"episode_index": value("int64"), "frame_index": value("int64"),
                             "timestamp": value("float64"), "index": value("int64"),
                             "task_index": value("int64"),
                             "state": {"names": list(STATES), "_type": "ClassLabel"},
                             "direction": {"names": list(DIRECTION_NAMES),
                                           "_type": "ClassLabel"}}
    for name, col in hub_columns(frames).items():
        feats[col] = value(_dtype(frames.field(name).type))
    for name in info.arrays:
        feats[IMAGE_KEYS[name]] = {"_type": "Image"}
    return feats


def lerobot_features(info: Any, frames: pa.Schema) -> dict[str, Any]:
    """info.json's `features`, LeRobot's way: per column its dtype, shape and names (images
    (height, width, channel), scalars (1,)), in the rows' column order."""
    h, w = info.resolution
    out: dict[str, Any] = {}
    for name, feat in datasets_features(info, frames).items():
        if feat["_type"] == "Image":
            array = next(a for a, k in IMAGE_KEYS.items() if k == name)
            extra: dict[str, Any] = {"vtsbench.encoding": ENCODINGS[array]}
            if array == "depth":
                extra["vtsbench.depth_scale_mm"] = info.depth_scale_mm
            out[name] = {"dtype": "image", "shape": [h, w, 3 if array == "rgb" else 1],
                         "names": ["height", "width", "channel"], "info": extra}
        else:
            labels = feat.get("names")
            out[name] = {"dtype": "int64" if labels else feat["dtype"], "shape": [1],
                         "names": labels}
    return out


def arrow_schema(info: Any, frames: pa.Schema) -> pa.Schema:
    """The arrow schema of every episode file: datasets' own (the `huggingface` metadata) and
    the layout's version and depth scale under the `vtsbench` key."""
    import datasets

    schema = datasets.Features.from_dict(datasets_features(info, frames)).arrow_schema
    doc: dict[str, Any] = {"episodes_hub_version": EPISODES_HUB_VERSION}
    if info.has_depth:
        doc["depth_scale_mm"] = info.depth_scale_mm
    return schema.with_metadata({**(schema.metadata or {}),
                                 b"vtsbench": json.dumps(doc).encode()})


def _parquet_options(schema: pa.Schema) -> dict[str, Any]:
    """As the samples' files: labels in zstd pages, images (compressed already) as they are."""
    images = set(IMAGE_KEYS.values())
    labels = [n for n in schema.names if n not in images]
    return {"compression": {n: "none" if n in images else "zstd" for n in schema.names},
            "compression_level": dict.fromkeys(labels, 3), "use_dictionary": labels,
            "write_statistics": labels}


# -- the files -----------------------------------------------------------------------------


def _labels_table(ds: VtsDataset, frames: pa.Schema) -> pa.Table:
    """Every frame's label columns, in store order: LeRobot's, then state and direction (-1
    where unknown), then the frames' own values."""
    import pyarrow as pa
    import pyarrow.compute as pc

    table = ds.episodes.frames
    index = ds.episodes.index
    lengths = index.column("length").to_numpy()
    objects = index.column("object").to_pylist()
    tasks = sorted(set(objects))
    task_of = np.repeat(np.asarray([tasks.index(o) for o in objects], np.int64), lengths)
    cols = {"episode_index": table.column("episode_index"),
            "frame_index": table.column("frame_index"),
            "timestamp": table.column("timestamp"),
            "index": pa.array(np.arange(len(table), dtype=np.int64)),
            "task_index": pa.array(task_of),
            "state": pc.fill_null(table.column("state"), -1).cast(pa.int64()),
            "direction": pc.fill_null(table.column("direction"), -1).cast(pa.int64())}
    for name, col in hub_columns(frames).items():
        cols[col] = table.column(name)
    return pa.table({k: v.combine_chunks() if isinstance(v, pa.ChunkedArray) else v
                     for k, v in cols.items()})


def _images(frames: list[bytes]) -> pa.Array:
    import pyarrow as pa

    image = pa.struct([("bytes", pa.binary()), ("path", pa.string())])
    return pa.array([{"bytes": b, "path": None} for b in frames], image)


def _encode(data: dict[str, np.ndarray], keep: np.ndarray, scale_mm: float
            ) -> dict[str, list[bytes]]:
    """The image columns of a window's real frames (keep: not padded)."""
    out = {IMAGE_KEYS["rgb"]: [tiff(f) for f in data["rgb"][keep]]}
    if "depth" in data:
        counts = stored_counts(data["depth"][keep], scale_mm).view(np.uint16)
        out[IMAGE_KEYS["depth"]] = [tiff(f, predictor=False) for f in counts]
        out[IMAGE_KEYS["contact"]] = [mask_png(f) for f in data["contact"][keep]]
    return out


def _frames_per_group(info: Any) -> int:
    """Frames per row group: about ROW_GROUP_BYTES of encoded images (from the decoded size,
    an upper bound: TIFF and PNG only shrink it)."""
    h, w = info.resolution
    per_frame = h * w * (3 + (3 if info.has_depth else 0))
    return max(1, int(ROW_GROUP_BYTES // max(1, per_frame * 0.6)))


def _fingerprint(ds: VtsDataset, schema: pa.Schema, opts: dict[str, Any], group: int) -> str:
    """sha256 of what every episode file depends on but its frames (see hub_write)."""
    from ..format.provenance import package_version

    doc = {"dataset_sha256": ds.info.dataset_sha256, "vtsbench": package_version(),
           "schema": hashlib.sha256(schema.serialize().to_pybytes()).hexdigest(),
           "options": repr(sorted(opts.items())), "group": group,
           "layout": EPISODES_HUB_VERSION}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()


def _write_file(path: Path, schema: pa.Schema, opts: dict[str, Any], group: int,
                tables: Iterator[pa.Table]) -> None:
    """One episode's parquet file from its row groups, through a temporary name."""
    import pyarrow.parquet as pq

    with replacing(path) as tmp, pq.ParquetWriter(tmp, schema, **opts) as writer:
        for table in tables:
            writer.write_table(table, row_group_size=group)


def _clean(folder: Path, keep: set[str], root: Path) -> None:
    """Remove the data files of another plan, unfinished ones and empty chunk folders."""
    if not folder.is_dir():
        return
    for p in sorted(folder.rglob("*"), reverse=True):
        if p.is_file() and p.relative_to(root).as_posix() not in keep:
            p.unlink()
        elif p.is_dir() and not any(p.iterdir()):
            p.rmdir()


def write_episodes(ds: VtsDataset, root: Path, workers: int = 1,
                   advance: Callable[[int], None] | None = None, state: Path | None = None,
                   shown: Path | None = None, digests: dict[str, str] | None = None,
                   kept: list[str] | None = None) -> EpisodesHub:
    """Write hf/episodes/ under root: one parquet file per episode (resumed as write_kind
    resumes: files whose marker matches are kept, listed in `kept`), then the meta files."""
    import pyarrow as pa

    from ..format.provenance import sha256_file

    info = ds.info
    eps = ds.episodes
    frames_schema = eps.frames.schema
    schema = arrow_schema(info, frames_schema)
    opts = _parquet_options(schema)
    group = _frames_per_group(info)
    base = _fingerprint(ds, schema, opts, group)
    index = eps.index
    starts = index.column("frame_start").to_numpy().astype(np.int64)
    lengths = index.column("length").to_numpy().astype(np.int64)
    rels = [episode_file(e) for e in range(len(eps))]
    fps = [hashlib.sha256(f"{base} {rel} {starts[e]} {lengths[e]}".encode()).hexdigest()
           for e, rel in enumerate(rels)]
    digests = {} if digests is None else digests
    files: dict[int, HubFile] = {}
    stats: dict[int, dict[str, Any]] = {}
    for e, rel in enumerate(rels):
        doc = kept_marker(root, rel, done_marker(state, rel), fps[e])
        if doc is not None and isinstance(doc.get("stats"), dict):
            files[e] = HubFile(rel, e, int(lengths[e]), doc["size"])
            digests[rel], stats[e] = doc["sha256"], doc["stats"]
            if kept is not None:
                kept.append(rel)
            if advance is not None:
                advance(int(lengths[e]))
    _clean(root / EPISODES_HUB / "data", {rels[e] for e in files}, root)
    labels = _labels_table(ds, frames_schema)
    wins = eps.windows(length=group, stride=group, pad="edge", arrays=info.arrays)
    jobs = [(int(e), k) for k, e in enumerate(wins.episode_index) if int(e) not in files]
    scale = info.depth_scale_mm

    def make(job: tuple[int, int]) -> tuple[int, pa.Table, dict[str, Moments]]:
        e, k = job
        data = wins.read([k], info.arrays)
        keep = ~data["pad_mask"][0]
        arrays = {n: data[n][0] for n in info.arrays}
        rows = starts[e] + data["frame_index"][0][keep]
        cols = {n: labels.column(n).take(pa.array(rows)) for n in labels.column_names}
        cols.update({n: _images(v) for n, v in _encode(arrays, keep, scale).items()})
        table = pa.Table.from_arrays([_as_type(cols[f.name], f.type) for f in schema],
                                     schema=schema)
        return e, table, image_moments({n: a[keep] for n, a in arrays.items()}, scale)

    current = -1
    try:
        for e, results in itertools.groupby(ordered(jobs, make, workers), key=lambda r: r[0]):
            current = e
            moments: dict[str, Moments] = {}

            def tables(rs: Iterator[Any], acc: dict[str, Moments] = moments
                       ) -> Iterator[pa.Table]:
                for _, table, part in rs:
                    for name, m in part.items():
                        acc.setdefault(name, Moments()).add(m)
                    yield table
                    if advance is not None:
                        advance(table.num_rows)

            path = root / rels[e]
            path.parent.mkdir(parents=True, exist_ok=True)
            _write_file(path, schema, opts, group, tables(results))
            ep_rows = labels.slice(int(starts[e]), int(lengths[e]))
            stats[e] = {**label_stats(ep_rows), **{
                IMAGE_KEYS[n]: m.doc(int(lengths[e]), True) for n, m in moments.items()}}
            size = path.stat().st_size
            files[e] = HubFile(rels[e], e, int(lengths[e]), size)
            digests[rels[e]] = sha256_file(path)
            marker = done_marker(state, rels[e])
            if marker is not None:
                marker.parent.mkdir(parents=True, exist_ok=True)
                write_bytes_atomic(marker, json.dumps(
                    {"fingerprint": fps[e], "size": size, "sha256": digests[rels[e]],
                     "stats": stats[e]}).encode())
    except OSError as err:
        raise write_failed(err, (shown or root) / rels[max(current, 0)]) from None
    hub = episodes_layout(ds, [files[e] for e in sorted(files)])
    write_meta(ds, root, frames_schema, [stats[e] for e in sorted(stats)])
    return hub


def episode_splits(ds: VtsDataset) -> dict[str, dict[str, list[int]]]:
    """The splits of episodes: scheme -> `datasets` split name -> episode indices (sorted)."""
    position = {eid: i for i, eid in enumerate(ds.episodes.ids)}
    out: dict[str, dict[str, list[int]]] = {}
    for name in ds.splits:
        split = ds.split_file(name)
        if split.kind != EPISODE:
            continue
        out[name] = {split_name(p): sorted(position[i] for i in split.parts[p])
                     for p in sorted(split.parts, key=part_key) if split.parts[p]}
    return out


def episodes_layout(ds: VtsDataset, files: list[HubFile]) -> EpisodesHub:
    """The episodes' configs: every frame (`episodes`, split `full`, the data files by glob)
    and one per split of episodes (`episodes_<scheme>`, without the scheme's `episode_`
    prefix, its parts' files)."""
    n = len(files)
    configs = {EPISODES_CONFIG: {"full": [EPISODES_GLOB]}}
    parts = {EPISODES_CONFIG: {"full": list(range(n))}}
    for scheme, split in episode_splits(ds).items():
        name = f"{EPISODES_CONFIG}_{scheme.removeprefix(EPISODE + '_')}"
        name = f"{EPISODES_CONFIG}_{scheme}" if name in configs else name
        configs[name] = {s: [files[e].path for e in eps] for s, eps in split.items()}
        parts[name] = split
    meta = [f"{EPISODES_HUB}/{rel}" for rel in EPISODES_META.values()]
    return EpisodesHub(files, meta, configs, parts)


def _jsonl(docs: list[dict[str, Any]]) -> bytes:
    return b"".join(json.dumps(d, allow_nan=False).encode() + b"\n" for d in docs)


def write_meta(ds: VtsDataset, root: Path, frames: pa.Schema, stats: list[dict[str, Any]]
               ) -> None:
    """meta/info.json, episodes.jsonl, tasks.jsonl and episodes_stats.jsonl of hf/episodes/,
    each written atomically."""
    info = ds.info
    rows = ds.episodes.index.to_pylist()
    tasks = sorted({r["object"] for r in rows})
    rates = sorted({float(r["fps"]) for r in rows})
    n, total = len(rows), sum(int(r["length"]) for r in rows)
    own: dict[str, Any] = {
        "episodes_hub_version": EPISODES_HUB_VERSION, "dataset": info.name,
        "dataset_version": info.dataset_version, "format_version": info.format_version,
        "dataset_sha256": info.dataset_sha256, "arrays": list(info.arrays),
        "sensors": sorted({r["sensor"] for r in rows}), "fps_by_episode": len(rates) > 1,
        "labels": {"state": list(STATES), "direction": list(DIRECTION_NAMES), "unknown": -1},
        "columns": {v: k for k, v in hub_columns(frames).items() if k != v},
        "splits": episode_splits(ds)}
    if info.has_depth:
        own["depth_scale_mm"] = info.depth_scale_mm
    doc = {"layout_of": LAYOUT_OF, "robot_type": None, "total_episodes": n,
           "total_frames": total, "total_tasks": len(tasks), "total_videos": 0,
           "total_chunks": -(-n // CHUNKS_SIZE), "chunks_size": CHUNKS_SIZE,
           "fps": rates[0] if len(rates) == 1 else None, "splits": {"full": f"0:{n}"},
           "data_path": EPISODE_DATA_PATH, "video_path": None,
           "features": lerobot_features(info, frames), "vtsbench": own}
    episodes = [{"episode_index": r["episode_index"], "tasks": [r["object"]],
                 "length": r["length"],
                 "vtsbench": {k: v for k, v in r.items() if k not in ("episode_index",
                                                                      "length")}}
                for r in rows]
    base = root / EPISODES_HUB
    (base / "meta").mkdir(parents=True, exist_ok=True)
    write_bytes_atomic(base / EPISODES_META["info"],
                       (json.dumps(doc, indent=4, allow_nan=False) + "\n").encode())
    write_bytes_atomic(base / EPISODES_META["episodes"], _jsonl(episodes))
    write_bytes_atomic(base / EPISODES_META["tasks"], _jsonl(
        [{"task_index": i, "task": t} for i, t in enumerate(tasks)]))
    write_bytes_atomic(base / EPISODES_META["stats"], _jsonl(
        [{"episode_index": e, "stats": s} for e, s in enumerate(stats)]))


def remove_episodes(root: Path) -> None:
    """No episodes: no hf/episodes/ (left by an export of an earlier version of the dataset)."""
    shutil.rmtree(root / EPISODES_HUB, ignore_errors=True)
