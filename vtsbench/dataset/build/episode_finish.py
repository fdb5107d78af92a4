"""Finishing a dataset of episodes: the frames store's last shard and metadata, the episode and
frame indexes, the static and slip kinds (empty: their index and Zarr group hold no sample, so
every reader of a dataset reads this one), info.json (format 1.2, with the episode counts), the
split files over the episodes (splits/episodes.py), card, every file's sha256, and the
rename of the partial folder to OUT (build/staging.py's commit, as a build finishes)."""

from __future__ import annotations

import json
import shutil
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ...atomic import write_bytes_atomic
from ...errors import VtsError
from ..format.arrays import Layout
from ..format.episodes import (
    EpisodeRecord,
    episode_counts,
    episodes_problems,
    episodes_table,
    frames_arrow_schema,
    table_bytes,
)
from ..format.index import index_bytes
from ..format.info import (
    EPISODES_FORMAT_VERSION,
    SAMPLE_STORAGE_EPISODES,
    VIEWS_FORMAT_VERSION,
    Counts,
    DatasetInfo,
    ZarrSettings,
    consistency_problems,
    dataset_checksum,
    info_schema_errors,
)
from ..format.layout import (
    CARD_PATH,
    CHECKSUMMED,
    EPISODES,
    EPISODES_GROUP,
    EPISODES_INDEX,
    FRAMES_INDEX,
    INFO_PATH,
    KINDS,
    SPLITS_DIR,
    episode_video_path,
    group_path,
    index_path,
)
from ..format.provenance import package_version, versions
from ..format.records import SplitFile
from ..splits.episodes import (
    EPISODE,
    check_episode_split,
    make_episode_splits,
    same_held_out,
    split_sizes,
)
from ..splits.files import write_splits
from ..splits.given import GIVEN, given_objects_split
from .card import codec_text, size_category
from .episode_samples import sample_splits, sample_views
from .episode_video import frames_codec
from .finish import hash_files
from .staging import commit
from .store import samples_per_shard, write_metadata

if TYPE_CHECKING:
    import pyarrow as pa

    from .episode_stage import FrameShards


def merged_kinds(records: Sequence[dict[str, Any]]) -> dict[str, str]:
    """The kind of every per-frame extra column over all episodes (int and float: float)."""
    out: dict[str, str] = {}
    for r in records:
        for name, kind in r["extra_kinds"].items():
            have = out.get(name)
            out[name] = "float" if "float" in (kind, have) and have is not None else kind
    return out


def frames_table(records: Sequence[dict[str, Any]]) -> pa.Table:
    """index/frames.parquet's rows: every frame of every episode, in store order."""
    import numpy as np
    import pyarrow as pa

    kinds = merged_kinds(records)
    lengths = [int(r["record"]["length"]) for r in records]
    cols: dict[str, Any] = {
        "episode_index": np.repeat(np.arange(len(records), dtype=np.int64), lengths),
        "frame_index": np.concatenate([np.arange(n, dtype=np.int64) for n in lengths]),
        "timestamp": np.concatenate([np.asarray(r["timestamps"], np.float64) for r in records]),
        "state": [s for r in records for s in r["state"]],
        "direction": [d for r in records for d in r["direction"]],
    }
    for name in sorted(kinds):
        cols[name] = [v for r, n in zip(records, lengths, strict=True)
                      for v in r["extra"].get(name, [None] * n)]
        if kinds[name] == "float":
            cols[name] = [None if v is None else float(v) for v in cols[name]]
    return pa.Table.from_pydict(cols, schema=frames_arrow_schema(kinds))


def finish_episodes(stage: Path, out: Path, shards: FrameShards,
                    records: Sequence[dict[str, Any]], *, name: str, dataset_version: str,
                    shard_mb: float, seed: int = 0, samples: Sequence[dict[str, Any]] = (),
                    frames_per_sequence: int = 8, given: Sequence[SplitFile] = (),
                    provenance: Mapping[str, Any] | None = None,
                    holdout_objects: Sequence[str] | None = None) -> DatasetInfo:
    """Write everything but the frames' shards, checksum it and rename the stage to OUT;
    seed: the split schemes' (the same episodes and seed give the same split files).

    samples (add_sample's records): the static frames and slip sequences of frames_per_sequence
    frames as views of the episode store (format 1.3): their indexes with episode_index and
    frame_row, no arrays of their own, the fixed split schemes over them and the `given`
    splits, and the episode splits named `episode_<scheme>`. provenance: created_by,
    calibration (a format.info.Calibration) and build keys of info.json, for a build.
    given: splits of static or slip samples (with samples only) or of episodes (kept under
    their own names), each leak-checked; holdout_objects: given_objects over the episodes and,
    with samples, over them too (unless `given` holds it), both holding out those objects."""
    shards.finalize()
    lay = shards.layout
    assert lay is not None
    size = lay.frame
    episodes = episodes_table([EpisodeRecord.from_dict(r["record"]) for r in records])
    frames = frames_table(records)
    for rel, table in ((EPISODES_INDEX, episodes), (FRAMES_INDEX, frames)):
        (stage / rel).parent.mkdir(parents=True, exist_ok=True)
        write_bytes_atomic(stage / rel, table_bytes(table))
    objects = sorted(set(episodes.column("object").to_pylist()))
    views = sample_views(samples, records, objects) if samples else None
    layouts, counts, t_slip = {}, Counts(), 1
    for kind in KINDS:  # no samples: an empty index and group; samples: views, no group
        t = (frames_per_sequence if views else 1) if kind == "slip" else None
        n = len(views[kind].metas) if views else 0
        layouts[kind] = Layout(kind, n, size, t, samples_per_shard(
            size, t, int(shard_mb * 2**20)), lay.level, lay.arrays)
        if views:
            shutil.rmtree(stage / group_path(kind), ignore_errors=True)
            write_bytes_atomic(stage / index_path(kind), views[kind].index_bytes(kind))
        else:
            write_metadata(stage / group_path(kind), layouts[kind])
            write_bytes_atomic(stage / index_path(kind), index_bytes(kind, []))
    layouts[EPISODES] = replace(lay, n=shards.committed)
    of_samples = [sp for sp in given if sp.kind in KINDS]
    source = next((str(sp.params.get("source", "")) for sp in of_samples if sp.name == GIVEN), "")
    try:
        splits = make_episode_splits(episodes, seed=seed, holdout_objects=holdout_objects,
                                     source=source)
        for sp in given:
            if sp.kind not in KINDS:
                check_episode_split(sp, episodes)
    except VtsError as e:
        raise VtsError(e.reason, e.path or out) from None
    skipped = dict(splits.skipped)
    if views:
        t_slip = frames_per_sequence
        metas = [m for k in KINDS for m in views[k].metas]
        try:
            if holdout_objects is not None and not any(sp.name == GIVEN for sp in of_samples):
                of_samples.append(given_objects_split(metas, holdout_objects, seed=seed))
        except VtsError as e:
            raise VtsError(e.reason, out) from None
        ours = sample_splits(views, frames_per_sequence, seed=seed, resolution=size,
                             given=of_samples)
        mine, theirs = ours.get(GIVEN), splits.get(GIVEN)
        differ = same_held_out(mine, theirs) if mine and theirs else []
        if differ:
            raise VtsError(differ[0], out)
        renamed = [replace(sp, name=f"{EPISODE}_{sp.name}") for sp in splits.splits]
        skipped = {**{f"{EPISODE}_{k}": v for k, v in skipped.items()}, **ours.skipped}
        counts = Counts.of(metas, ours.splits)
        splits.splits = [*ours.splits, *renamed]
    splits.splits += [sp for sp in given if sp.kind not in KINDS]
    names = [sp.name for sp in splits.splits]
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup is not None:
        raise VtsError(f"two splits named {dup!r} (a scheme's and a given one, or two given)",
                       out)
    split_dir = stage / SPLITS_DIR
    if split_dir.is_dir():  # a finish that failed before: its files go, the new ones come
        for p in split_dir.glob("*.json"):
            p.unlink()
    split_sha = write_splits(split_dir, splits.splits) if splits.splits else {}
    prov = dict(provenance or {})
    build = {"writer": "vtsbench.create", "arrays": list(lay.arrays),
             "compression_level": lay.level, "shard_mb": shard_mb, "split_seed": seed,
             "splits_skipped": dict(sorted(skipped.items())), "versions": versions(),
             **prov.get("build", {})}
    info = DatasetInfo(
        name=name, vtsbench_version=package_version(), frames_per_sequence=t_slip,
        resolution=size, objects=objects,
        counts=replace(counts, splits=dict(split_sizes(splits.splits))), splits=split_sha,
        shapes={k: {n: v.shape(n) for n in v.arrays} for k, v in layouts.items()},
        zarr=ZarrSettings({k: v.samples_per_shard for k, v in layouts.items()
                           if not views or k == EPISODES},
                          "zstd" if lay.level else "none", lay.level),
        dataset_version=dataset_version,
        created_by=prov.get("created_by", "vtsbench.create"),
        calibration=prov.get("calibration"), build=build,
        format_version=VIEWS_FORMAT_VERSION if views else EPISODES_FORMAT_VERSION,
        episodes=replace(episode_counts(episodes, frames), video=frames_codec(shards)),
        sample_storage=SAMPLE_STORAGE_EPISODES if views else None)
    _refuse(consistency_problems(info) + episodes_problems(episodes, frames, info), stage)
    content = hash_files(stage, lambda rel: rel.startswith(CHECKSUMMED))
    info.dataset_sha256 = dataset_checksum(content)
    write_bytes_atomic(stage / CARD_PATH, card_text(info).encode("utf-8"))
    info.files = {**content, **hash_files(
        stage, lambda rel: not rel.startswith(CHECKSUMMED) and rel != INFO_PATH)}
    _refuse(info_schema_errors(info.to_dict()), stage)
    (stage / INFO_PATH).parent.mkdir(exist_ok=True)
    write_bytes_atomic(stage / INFO_PATH, info.to_json().encode())
    commit(stage, out)
    return info


def _refuse(bad: list[str], stage: Path) -> None:
    """What the writer would put in info.json contradicts the format: a one-line error (the
    partial folder stays, so nothing saved is lost)."""
    if bad:
        raise VtsError(f"{bad[0]}{f' (and {len(bad) - 1} more)' if len(bad) > 1 else ''}",
                       stage / INFO_PATH)


def card_text(info: DatasetInfo) -> str:
    """README.md of a dataset of episodes: YAML header (its configs read the two episode
    indexes) and what it holds."""
    ep = info.episodes
    assert ep is not None
    h, w = info.resolution
    depth = info.has_depth
    head = "\n".join([
        "---", f"pretty_name: {json.dumps(info.name)}", "license: unknown",
        "task_categories:", "- video-classification", "size_categories:",
        f"- {size_category(ep.episodes)}", "tags:", "- tactile", "- visuo-tactile",
        "- rgb-d" if depth else "- rgb", "- vtsbench", "- episodes", "configs:",
        "- config_name: episodes", "  data_files:", "  - split: index",
        f"    path: {EPISODES_INDEX}", "  default: true", "- config_name: frames",
        "  data_files:", "  - split: index", f"    path: {FRAMES_INDEX}",
        *[line for kind in (KINDS if info.views else ()) for line in (
            f"- config_name: {kind}", "  data_files:", "  - split: index",
            f"    path: {index_path(kind)}")], "---", ""])
    views = (f"\nIts {info.counts.static.samples} static frames and {info.counts.slip.samples} "
             f"slip sequences of {info.frames_per_sequence} frames are views of those frames, "
             f"stored once: `{index_path('static')}` and `{index_path('slip')}` give each "
             "sample's episode (`episode_index`) and the row of its first frame "
             "(`frame_row`).\n" if info.views else "")
    comp = f"zstd level {info.zarr.level}" if info.zarr.level else "none"
    return head + f"""
# {info.name}

Visuo-tactile episodes written by `{info.created_by}` (dataset version {info.dataset_version},
format {info.format_version}): {ep.episodes} continuous takes, {ep.frames} frames of {h}x{w},
each frame stored once; windows of any length, stride or time offsets are chosen when reading.
{views}
| episodes | frames | objects | sessions | dropped frames |
|---:|---:|---:|---:|---:|
| {ep.episodes} | {ep.frames} | {len(ep.objects)} | {len(ep.sessions)} | {ep.dropped_frames} |

Objects: {", ".join(info.objects)}.

## Loading

```python
import vtsbench
ds = vtsbench.load("path/to/this/folder")
print(ds.episodes.index)                      # one row per episode
clips = ds.episodes.windows(length=8, stride=8)
clip = clips[0]                               # rgb (8, H, W, 3), timestamps, labels
```

## Arrays

{_arrays_text(info, comp)}

## Provenance

- vtsbench {info.vtsbench_version}; per-file sha256 and the content checksum in `{INFO_PATH}`
- dataset_sha256: `{info.dataset_sha256}`

Check a copy with `vtsbench verify <folder>`; summarise it with `vtsbench info <folder>`.
"""


def _arrays_text(info: DatasetInfo, comp: str) -> str:
    """The card's words on how the frames are stored: every array in the Zarr group, or the
    RGB as one video per episode (codec and settings) and the other arrays in Zarr."""
    import textwrap

    sps = info.zarr.samples_per_shard[EPISODES]
    rows = (f"Row r is row r of `{FRAMES_INDEX}` (timestamp in seconds from the\nepisode start, "
            f"state, direction); `{EPISODES_INDEX}` gives each episode's first row\n"
            "(`frame_start`) and `length`.")
    codec = info.episodes.video if info.episodes is not None else None
    if codec is None:
        arrays = ("`rgb` (uint8, RGB), `depth` (int16; value x "
                  f"{info.depth_scale_mm} = mm) and `contact` (bool)" if info.has_depth
                  else "`rgb` (uint8, RGB) only: no depth or contact")
        return (f"`{EPISODES_GROUP}` is a Zarr v3 group with {arrays}: every frame of every "
                f"episode in episode\norder, one frame per chunk, shards of {sps} frames, {comp}"
                f"\nwith a crc32c per chunk. {rows}")
    first, second = (episode_video_path(k, codec.suffix) for k in (0, 1))
    group = (f"Depth and contact stay lossless: `{EPISODES_GROUP}` is a Zarr v3 group with "
             f"`depth` (int16; value x {info.depth_scale_mm} = mm) and `contact` (bool), every "
             f"frame of every episode in episode order, one frame per chunk, shards of {sps} "
             f"frames, {comp} with a crc32c per chunk, and" if info.has_depth
             else f"`{EPISODES_GROUP}` is a Zarr v3 group holding")
    text = (f"The RGB frames are stored as video, one file per episode named by its index "
            f"(`{first}`, `{second}`, ...; frame k of the file is frame k of the episode, at "
            f"its fps): {codec_text(codec)}. {group} the metadata of `rgb` alone (its frames' "
            "count and size, no chunk): read the RGB through `vtsbench.load` or the videos, "
            f"not a generic Zarr reader. {rows.replace(chr(10), ' ')}")
    return textwrap.fill(text, 95, break_long_words=False, break_on_hyphens=False)
