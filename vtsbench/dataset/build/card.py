"""The dataset card (README.md) and the preview parquet files for the Hugging Face Hub.

The card's YAML `configs` make `datasets.load_dataset(OUT)` read the slip index (the default
config), the static index, and two small previews whose images are PNG bytes in the `Image()`
feature, so the Hub viewer shows frames, depth and contact. Everything is derived from the
plan and info, with fixed encoder settings: the same build gives the same bytes.
`storage_line` and `codec_text` say how a dataset's frames are stored (Zarr; the episodes' RGB
as video, with the codec and its settings; format 1.3's samples as views of the episodes), for
the cards (this one and build/episode_finish.py's) and `vtsbench info`.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ...atomic import write_bytes_atomic
from ..format.episode_video import stored_codec
from ..format.layout import (
    ARRAYS,
    BUILD_REPORT_PATH,
    CARD_PATH,
    DEPTH_SCALE_MM,
    INFO_PATH,
    KINDS,
    PREVIEW_DIR,
    SPLITS_DIR,
    VIDEOS_DIR,
    group_path,
    index_path,
    preview_path,
)
from .png import depth_preview_pngs, encode_png

if TYPE_CHECKING:
    from ..format.info import DatasetInfo
    from ..format.video import VideoCodec
    from .plan import Plan

@dataclass(frozen=True)
class HubCard:
    """What the Hugging Face copy (`vtsbench export-hf`) adds to the card: its YAML config
    lines (listed first, one of them the default) and its section."""

    configs: list[str]
    section: str


#: Samples shown per kind (evenly spaced rows): full-size PNGs, so few for slip (T frames).
PREVIEW_SAMPLES = {"static": 8, "slip": 4}
META_COLUMNS = {"static": ("sample_id", "row", "object", "class_idx", "session"),
                "slip": ("sample_id", "row", "object", "class_idx", "session", "state",
                         "direction")}


def preview_rows(n: int, k: int) -> list[int]:
    """Up to k evenly spaced rows of n, first and last included."""
    if n <= 0:
        return []
    return sorted({round(float(x)) for x in np.linspace(0, n - 1, min(n, k))})




def _frame_png(name: str, frame: np.ndarray) -> bytes:
    """One frame of an array as a PNG: RGB; contact as 0/255 (depth: frame_pngs)."""
    if name == "rgb":
        return encode_png(frame, "sub")
    return encode_png(frame.astype(np.uint8) * np.uint8(255), "none")


def preview_schema(kind: str, arrays: tuple[str, ...] = ARRAYS) -> Any:
    """The arrow schema of a kind's preview, with the `huggingface` features metadata that makes
    datasets decode the PNG columns as Image() (a list of images per slip sample).

    Written by hand, not through datasets.Features, so a build never imports datasets; the
    `Sequence` spelling is read by datasets 3 and later.
    """
    import json

    import pyarrow as pa

    image = pa.struct([("bytes", pa.binary()), ("path", pa.string())])
    cols = [("sample_id", pa.string()), ("row", pa.int64()), ("object", pa.string()),
            ("class_idx", pa.int32()), ("session", pa.string())]
    if kind == "slip":
        cols += [("state", pa.string()), ("direction", pa.int32())]
    feats: dict[str, Any] = {n: {"dtype": str(t), "_type": "Value"} for n, t in cols}
    for name in arrays:
        if kind == "slip":
            cols.append((name, pa.list_(image)))
            feats[name] = {"feature": {"_type": "Image"}, "_type": "Sequence"}
        else:
            cols.append((name, image))
            feats[name] = {"_type": "Image"}
    meta = {"huggingface": json.dumps({"info": {"features": feats}})}
    return pa.schema(cols, metadata=meta)


def frame_pngs(name: str, sample: np.ndarray, sequence: bool) -> list[bytes]:
    """The PNGs of one sample of an array: one per frame of a slip sample, one for static.

    Depth (the stored int16 counts) is colour-mapped on one scale per sample
    (png.depth_preview_pngs): a 16-bit grey PNG of micrometres displayed all black."""
    if name == "depth":
        return depth_preview_pngs(sample.astype(np.float32) * np.float32(DEPTH_SCALE_MM))
    return [_frame_png(name, f) for f in sample] if sequence else [_frame_png(name, sample)]


Pngs = dict[int, dict[str, list[bytes]]]


def preview_bytes(root: Path, plan: Plan, kind: str, workers: int = 1,
                  pngs: Pngs | None = None) -> bytes:
    """The parquet file of a kind's preview. `pngs` holds the PNGs the shard tasks made (row ->
    array -> frames); any other preview row is read back from the arrays just written and
    encoded here by `workers` threads (OpenCV releases the GIL)."""
    from concurrent.futures import ThreadPoolExecutor

    import pyarrow as pa
    import pyarrow.parquet as pq

    from ..read.store import open_group

    seq = kind == "slip"
    arrays = plan.layouts[kind].arrays
    rows = preview_rows(plan.layouts[kind].n, PREVIEW_SAMPLES[kind])
    have = dict(pngs or {})
    missing = [r for r in rows if r not in have]
    if missing:
        group = open_group(root, kind)
        jobs = [(r, name, group[name][r]) for r in missing for name in arrays]
        with ThreadPoolExecutor(max(1, workers)) as pool:
            made = list(pool.map(lambda job: frame_pngs(job[1], job[2], seq), jobs))
        for (r, name, _), images in zip(jobs, made, strict=True):
            have.setdefault(r, {})[name] = images
    records = []
    for r in rows:
        meta = plan.metas[kind][r].to_row()
        rec: dict[str, Any] = {c: meta[c] for c in META_COLUMNS[kind]}
        for name in arrays:
            images = [{"bytes": b, "path": None} for b in have[r][name]]
            rec[name] = images if seq else images[0]
        records.append(rec)
    table = pa.Table.from_pylist(records, schema=preview_schema(kind, arrays))
    buf = io.BytesIO()
    pq.write_table(table, buf, compression="none", row_group_size=1)
    return buf.getvalue()


def write_preview(root: Path, plan: Plan, workers: int = 1,
                  pngs: dict[str, Pngs] | None = None) -> None:
    """preview/static.parquet and preview/slip.parquet (pngs: per kind, see preview_bytes)."""
    (root / PREVIEW_DIR).mkdir(exist_ok=True)
    for kind in KINDS:
        write_bytes_atomic(root / preview_path(kind),
                           preview_bytes(root, plan, kind, workers, (pngs or {}).get(kind)))


def size_category(n: int) -> str:
    """The Hub's size_categories value for n rows."""
    for limit, name in ((1_000, "n<1K"), (10_000, "1K<n<10K"), (100_000, "10K<n<100K"),
                        (1_000_000, "100K<n<1M"), (10_000_000, "1M<n<10M")):
        if n < limit:
            return name
    return "n>10M"


def codec_text(codec: VideoCodec) -> str:
    """A video codec in words: its name, encoder and settings, and what decoding gives back."""
    opts = ", ".join(f"{k} {v}" for k, v in codec.options.items())
    every = f"a keyframe every {codec.gop} frames" if codec.gop > 1 else "every frame a keyframe"
    return (f"{codec.name} (FFmpeg {codec.codec}, {codec.pix_fmt}, {opts}; {every}; "
            f"{codec.container} {codec.suffix}), "
            + ("lossless: decoding gives the frames back bit for bit" if codec.lossless
               else "lossy: the decoded frames are near, not equal to, the frames written"))


def storage_line(info: DatasetInfo) -> str:
    """How the frames are stored, in one line: Zarr (compression), or the episodes' RGB as
    video (codec and settings) with depth and contact in Zarr; for format 1.3 that the static
    and slip samples are views of the episode store."""
    comp = (f"zstd level {info.zarr.level}" if info.zarr.level else "uncompressed") + \
        ", a crc32c per chunk"
    codec = stored_codec(info)
    if codec is None:
        line = f"Zarr v3 ({comp})"
    else:
        rest = [a for a in info.arrays if a != "rgb"]
        line = (f"RGB as video, one file per episode in {VIDEOS_DIR}/: {codec_text(codec)}; "
                + (f"{' and '.join(rest)} in Zarr v3 ({comp})" if rest
                   else "no depth or contact"))
    if info.views:
        line += ("; the static and slip samples are views of the episode store (each frame "
                 "stored once, no arrays of their own)")
    return line


def _configs(plan: Plan, hub: HubCard | None = None) -> str:
    """The YAML `configs` list: the hub configs first when there is a hub copy (the first slip
    scheme is the default), then the indexes (the slip index is the default without a hub
    copy) and the previews."""
    lines = ["configs:"]
    if hub is not None:
        lines += hub.configs
    for kind in ("slip", "static"):
        if not plan.layouts[kind].n:
            continue
        lines += [f"- config_name: {kind}", "  data_files:", "  - split: index",
                  f"    path: {index_path(kind)}"]
        if hub is None and (kind == "slip" or not plan.layouts["slip"].n):
            lines.append("  default: true")
    for kind in ("slip", "static"):
        if plan.layouts[kind].n:
            lines += [f"- config_name: preview_{kind}", "  data_files:", "  - split: preview",
                      f"    path: {preview_path(kind)}"]
    return "\n".join(lines)


def _yaml_str(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


#: Hub task categories of every vtsbench dataset (object classes, slip state and direction of a
#: sequence, depth from the RGB images).
TASK_CATEGORIES = ("image-classification", "video-classification", "depth-estimation")


def card_text(info: DatasetInfo, plan: Plan, hub: HubCard | None = None,
              license: str = "unknown") -> str:
    """README.md: YAML header (license, task categories, size, configs) and a human
    description of the dataset; with `hub` (export-hf) its configs and section."""
    lay = plan.layouts
    t = info.frames_per_sequence
    h, w = info.resolution
    depth = info.has_depth
    n = sum(lay[k].n for k in KINDS)
    tasks = TASK_CATEGORIES if depth else TASK_CATEGORIES[:2]
    head = "\n".join(["---", f"pretty_name: {_yaml_str(info.name)}",
                      f"license: {license}", "task_categories:", *(f"- {c}" for c in tasks),
                      "size_categories:", f"- {size_category(n)}",
                      "tags:", "- tactile", "- visuo-tactile", "- rgb-d" if depth else "- rgb",
                      "- vtsbench", _configs(plan, hub), "---", ""])
    rows = "\n".join(
        f"| {k} | {lay[k].n} | {lay[k].n * (lay[k].frames or 1)} | "
        f"{' x '.join(map(str, lay[k].shape('rgb')))} | {lay[k].samples_per_shard} |"
        for k in KINDS)
    splits = "\n".join(
        f"| `{name}` | {', '.join(f'{p} {n}' for p, n in parts.items())} | "
        f"`{info.splits[name][:16]}` |" for name, parts in info.counts.splits.items())
    cal = info.calibration
    comp = f"zstd level {info.zarr.level}" if info.zarr.level else "none"
    groups = f"`{group_path('static')}` and `{group_path('slip')}`"
    if depth:
        what = f"""\
Visuo-tactile RGB-D dataset built by `vtsbench build` (dataset version {info.dataset_version},
format {info.format_version}). Every RGB frame ({h}x{w}) is paired one to one with a depth map
generated by the sensor's calibration and a contact mask."""
        arrays = f"""\
{groups} are Zarr v3 groups with `rgb` (uint8, RGB),
`depth` (int16; value x {info.depth_scale_mm} = mm of indentation into the gel) and `contact`
(bool), one sample per chunk, shards of whole samples, {comp} with a crc32c per chunk. Row r of
each array is row r of `{index_path("<kind>")}`.

The preview tables hold PNGs: `rgb` as RGB, `depth` colour-mapped (viridis, 0 up to the
sample's maximum depth or 0.05 mm, whichever is larger; negative depth shown as 0) and `contact`
as 0/255."""
        provenance = f"""\
- calibration: sensor `{cal.sensor if cal else "-"}`, method `{cal.method if cal else "-"}`,
  depth solver `{info.build.get("solver", "-")}`"""
    else:
        what = f"""\
Visuo-tactile RGB dataset built by `vtsbench build --no-depth` (dataset version
{info.dataset_version}, format {info.format_version}): RGB frames ({h}x{w}) only, with **no depth
and no contact arrays** (the sensor had no calibration)."""
        arrays = f"""\
{groups} are Zarr v3 groups with `rgb` (uint8, RGB) only: no
`depth` or `contact` array. One sample per chunk, shards of whole samples, {comp} with a crc32c
per chunk. Row r of `rgb` is row r of `{index_path("<kind>")}`.

The preview tables hold the RGB frames as PNGs."""
        provenance = "- no calibration, no depth: built with `--no-depth`"
        unknown = sum(m.mm_per_px_x is None for m in plan.samples)
        if unknown:
            provenance += (f"\n- scale unknown (no mm_per_px in the recordings): "
                           f"`mm_per_px_x`, `mm_per_px_y` are null for {unknown} samples")
    return head + f"""
# {info.name}

{what}
Static samples are single frames; slip samples are sequences of {t} frames labelled static,
press or slip, with a slip direction, where the recordings have labels (null otherwise).

| kind | samples | frames | rgb shape | samples per shard |
|---|---:|---:|---|---:|
{rows}

Objects ({len(info.objects)}, `class_idx` is the index in this sorted list):
{", ".join(info.objects) or "(none)"}.

## Loading

```python
import vtsbench
ds = vtsbench.load("path/to/this/folder")   # arrays, index, fixed splits
train = ds.split("unseen_objects", "train")

import datasets
index = datasets.load_dataset("path/to/this/folder", "slip")          # the parquet index
preview = datasets.load_dataset("path/to/this/folder", "preview_slip")  # a few samples, PNGs
```

{hub.section if hub is not None else ""}## Arrays

{arrays}

## Splits

Made once at build time (seed {info.build.get("seed", 0)}), stored in `{SPLITS_DIR}/` and
checked for leaks:

| split | parts | sha256 |
|---|---|---|
{splits}

## Provenance

{provenance}
- vtsbench {info.vtsbench_version}; build parameters, per-file sha256 and the content checksum
  in `{INFO_PATH}`; skipped recordings in `{BUILD_REPORT_PATH}`
- dataset_sha256: `{info.dataset_sha256}`

Check a copy with `vtsbench verify <folder>`; summarise it with `vtsbench info <folder>`.
"""


def write_card(root: Path, info: DatasetInfo, plan: Plan) -> None:
    """Write README.md."""
    write_bytes_atomic(root / CARD_PATH, card_text(info, plan).encode("utf-8"))


def plan_of(info: DatasetInfo, index: dict[str, Any]) -> Any:
    """A Plan-like view of a built dataset (layouts from info.json, samples from the index
    tables), enough to write its card again."""
    from types import SimpleNamespace

    from ..format.arrays import Layout
    from ..format.records import SampleMeta

    layouts = {k: Layout(k, info.shapes[k]["rgb"][0], tuple(info.resolution),
                         info.frames_per_sequence if k == "slip" else None,
                         info.zarr.samples_per_shard[k], info.zarr.level, info.arrays)
               for k in KINDS}
    samples = [SampleMeta.from_row(r, k) for k in KINDS for r in index[k].to_pylist()]
    return SimpleNamespace(layouts=layouts, samples=samples)
