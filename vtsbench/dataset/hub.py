"""`vtsbench export-hf`: every sample of a built dataset in parquet under `hf/`, for `datasets`.

One parquet set per kind holds each sample once. The samples are grouped into *cells*: the
samples that fall in the same part of every split scheme of their kind (e.g. train of
unseen_objects, test of seen, fold3 of object_folds). Each cell is written to its own files, so
every split of every scheme is a list of whole files: the card's YAML `configs` give
`slip_<scheme>` and `static_<scheme>` configs whose splits point at those files, and no sample is
stored twice however many schemes hold it.

Columns: the index's labels (object, state and direction as ClassLabel ids), `rgb` as PNG images
(a list of T for a slip sample; lossless uint8), `depth` as float32 mm (exactly the loader's
values: the stored int16 counts x 0.001), `contact` as 1-bit PNG images (decoding to bool),
and `depth_preview`, a colour-mapped PNG of the depth for the Hub viewer. The arrow schema
carries the `huggingface` features metadata.
"""

from __future__ import annotations

import contextlib
import re
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import VtsError
from ..labels import DIRECTION_NAMES, STATES
from .hub_layout import HUB_DIR, HubFile, HubLayout
from .png import depth_preview_pngs, png
from .schema import INDEX_COLUMNS, INFO_PATH, KINDS

if TYPE_CHECKING:
    import pyarrow as pa

    from .loader import View, VtsDataset

#: Encoded bytes per row group (the Hub viewer reads one row group at a time) and per file.
ROW_GROUP_BYTES = 16 * 2**20
FILE_BYTES = 256 * 2**20
#: Parts of a split scheme -> split names of `datasets` (train, validation, test; folds as is).
SPLIT_NAMES = {"val": "validation"}
#: Index columns written as they are (the labels with names are ClassLabel columns).
PLAIN_COLUMNS = ("sample_id", "row", "session", "sensor", "mm_per_px_x", "mm_per_px_y",
                 "press_depth_mm", "contact_x_px", "contact_y_px")
SLIP_PLAIN = ("motion_dx_mm", "motion_dy_mm")


def config_name(kind: str, scheme: str) -> str:
    """The `datasets` config of a split scheme: `<kind>_<scheme>`, without repeating the kind
    (static_sessions stays static_sessions)."""
    return scheme if scheme.startswith(f"{kind}_") else f"{kind}_{scheme}"


def split_name(part: str) -> str:
    """The `datasets` split of a part: val -> validation; train, test, foldK unchanged; any
    character datasets refuses in a split name (not a letter, digit or _) becomes _."""
    return re.sub(r"\W", "_", SPLIT_NAMES.get(part, part), flags=re.ASCII)



# -- schema --------------------------------------------------------------------------------


def features_doc(info: Any, kind: str, extra: Sequence[str] = ()) -> dict[str, Any]:
    """The `datasets` features (as the JSON datasets writes) of a kind's hub files; extra: the
    index's own string columns (pattern fields, `take`, meta keys), after `source`."""
    seq = kind == "slip"
    t = info.frames_per_sequence
    h, w = info.resolution

    def value(dtype: str) -> dict[str, Any]:
        return {"dtype": dtype, "_type": "Value"}

    def maybe_list(feat: dict[str, Any]) -> dict[str, Any]:
        return {"feature": feat, "length": t, "_type": "Sequence"} if seq else feat

    feats: dict[str, Any] = {
        "sample_id": value("string"), "row": value("int64"),
        "object": {"names": list(info.objects), "_type": "ClassLabel"},
        "session": value("string"), "sensor": value("string"),
        "mm_per_px_x": value("float64"), "mm_per_px_y": value("float64"),
        "press_depth_mm": value("float64"), "contact_x_px": value("float64"),
        "contact_y_px": value("float64")}
    if seq:
        feats["state"] = {"names": list(STATES), "_type": "ClassLabel"}
        feats["direction"] = {"names": list(DIRECTION_NAMES), "_type": "ClassLabel"}
        feats["motion_dx_mm"] = value("float64")
        feats["motion_dy_mm"] = value("float64")
    feats["source"] = value("string")
    for name in extra:
        feats[name] = value("string")
    feats["rgb"] = maybe_list({"_type": "Image"})
    if info.has_depth:
        shape = [t, h, w] if seq else [h, w]
        array = "Array3D" if seq else "Array2D"
        feats["depth"] = {"shape": shape, "dtype": "float32", "_type": array}
        feats["contact"] = maybe_list({"_type": "Image"})
        feats["depth_preview"] = maybe_list({"_type": "Image"})
    return feats


def extra_columns(view: View) -> list[str]:
    """The index columns of a view beyond the fixed ones (the recordings' own fields)."""
    return [n for n in view.index.column_names if n not in INDEX_COLUMNS]


def arrow_schema(info: Any, kind: str, extra: Sequence[str] = ()) -> pa.Schema:
    """The arrow schema of a kind's hub files: datasets' own (its extension types for the
    depth array, so that `load_dataset` gives it back as Array2D/3D, and the
    `huggingface` features metadata), with the depth unit on the depth field."""
    import datasets

    schema = datasets.Features.from_dict(features_doc(info, kind, extra)).arrow_schema
    if "depth" in schema.names:
        i = schema.get_field_index("depth")
        meta = {"units": "mm", "meaning": "indentation into the gel, positive into the gel",
                "stored_as": f"int16 counts x {info.depth_scale_mm} mm"}
        schema = schema.set(i, schema.field(i).with_metadata(meta))
    return schema


def _nested(arr: np.ndarray) -> pa.Array:
    """(n, *dims) numpy -> arrow list<list<...>> of n rows, without a Python object per value."""
    import pyarrow as pa

    out: pa.Array = pa.array(np.ascontiguousarray(arr).reshape(-1))
    for d in reversed(arr.shape[1:]):
        n = len(out) // d
        out = pa.ListArray.from_arrays(pa.array(np.arange(0, (n + 1) * d, d, dtype=np.int32)),
                                       out)
    return out


# -- cells ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Cell:
    """Samples of one kind that share their part in every scheme (None: not in the scheme)."""

    parts: tuple[str | None, ...]
    positions: np.ndarray


def schemes_of(ds: VtsDataset, kind: str) -> list[str]:
    """The split schemes of a kind, by name."""
    return [s for s in ds.splits if ds.split_file(s).kind == kind]


def cells(ds: VtsDataset, kind: str) -> list[Cell]:
    """The cells of a kind in order of their first sample (index order inside each)."""
    n = len(ds.view(kind))
    schemes = schemes_of(ds, kind)
    keys: list[list[str | None]] = [[None] * len(schemes) for _ in range(n)]
    for j, scheme in enumerate(schemes):
        split = ds.split_file(scheme)
        for part in ds.parts(scheme):
            for p in ds._part_positions(split, part):
                keys[int(p)][j] = part
    groups: dict[tuple[str | None, ...], list[int]] = {}
    for p, key in enumerate(keys):
        groups.setdefault(tuple(key), []).append(p)
    return [Cell(k, np.asarray(v, np.int64)) for k, v in groups.items()]


# -- writing -------------------------------------------------------------------------------


def _label_columns(view: View, kind: str) -> dict[str, pa.Array]:
    """The label columns of a view's samples, in schema order (without the arrays)."""
    import pyarrow as pa

    idx = view.index
    cols: dict[str, pa.Array] = {}
    for name in PLAIN_COLUMNS[:2]:
        cols[name] = idx.column(name).combine_chunks()
    cols["object"] = idx.column("class_idx").cast(pa.int64()).combine_chunks()
    for name in PLAIN_COLUMNS[2:]:
        cols[name] = idx.column(name).combine_chunks()
    if kind == "slip":
        cols["state"] = idx.column("state_idx").cast(pa.int64()).combine_chunks()
        cols["direction"] = idx.column("direction").cast(pa.int64()).combine_chunks()
        for name in SLIP_PLAIN:
            cols[name] = idx.column(name).combine_chunks()
    for name in ("source", *extra_columns(view)):
        cols[name] = idx.column(name).combine_chunks()
    return cols


def _encode_sample(rgb: np.ndarray, depth: np.ndarray | None, contact: np.ndarray | None
                   ) -> dict[str, list[bytes]]:
    """PNGs of one sample (one per frame; one for a static sample): rgb, contact (1-bit) and
    the depth preview."""
    out = {"rgb": [png(f) for f in (rgb if rgb.ndim == 4 else rgb[None])]}
    if depth is not None and contact is not None:
        out["contact"] = [mask_png(f) for f in (contact if contact.ndim == 3 else contact[None])]
        out["depth_preview"] = depth_preview_pngs(depth)
    return out


def mask_png(mask: np.ndarray) -> bytes:
    """A bool mask as a 1-bit PNG, which PIL decodes to mode "1" and numpy to bool again:
    1.6 ms and 2.3 kB a 480x640 contact mask, where a parquet bool array costs 5 ms to write
    (its nesting levels) and the Hub viewer cannot show it."""
    import cv2

    ok, buf = cv2.imencode(".png", mask.astype(np.uint8), [cv2.IMWRITE_PNG_BILEVEL, 1])
    if not ok:
        raise ValueError("cannot encode PNG")
    return buf.tobytes()


def _images(pngs: list[list[bytes]], seq: bool) -> pa.Array:
    import pyarrow as pa

    image = pa.struct([("bytes", pa.binary()), ("path", pa.string())])
    if seq:
        return pa.array([[{"bytes": b, "path": None} for b in s] for s in pngs],
                        pa.list_(image, len(pngs[0]) if pngs else -1))
    return pa.array([{"bytes": s[0], "path": None} for s in pngs], image)


def _batch(view: View, schema: pa.Schema) -> pa.Table:
    """The table of a view's samples: read in one zarr call, PNGs encoded here (OpenCV and
    the zarr codecs release the GIL, so batches are made by several threads at once)."""
    import pyarrow as pa

    kind = view.kind
    data = view.read(slice(None), view.arrays)
    depth, contact = data.get("depth"), data.get("contact")
    encoded = [_encode_sample(data["rgb"][i], None if depth is None else depth[i],
                              None if contact is None else contact[i]) for i in range(len(view))]
    cols = _label_columns(view, kind)
    seq = kind == "slip"
    for name in encoded[0]:
        cols[name] = _images([e[name] for e in encoded], seq)
    if depth is not None:
        cols["depth"] = _nested(depth)
    return pa.Table.from_arrays([_as_type(cols[f.name], f.type) for f in schema], schema=schema)


def _as_type(arr: pa.Array, typ: pa.DataType) -> pa.Array:
    """An array of the field's type: datasets' extension arrays wrap their storage."""
    import pyarrow as pa

    if isinstance(typ, pa.ExtensionType):
        return pa.ExtensionArray.from_storage(typ, arr.cast(typ.storage_type))
    return arr.cast(typ)


def _rows_per(view: View, target: int, encoded_ratio: float = 1.0) -> int:
    """Rows per `target` bytes, from the decoded size of a sample (an upper bound of its
    encoded size: PNG and zstd only shrink it)."""
    return max(1, int(target // max(1, view.nbytes() * encoded_ratio)))


def _parquet_options(schema: pa.Schema) -> dict[str, Any]:
    """zstd pages; dictionaries and statistics for the label columns only.

    The depth (float32 mm, 480x640 frames, one core): dictionary encoding 33 ms and 42 kB a
    frame, plain 6.3 ms and 61 kB, byte-stream-split 13 ms and 115 kB (the counts x 0.001 have
    noisy low mantissa bytes): plain, at a fifth of the time for 45 % more bytes of depth.
    """
    labels = [f.name for f in schema if f.name not in ("rgb", "depth", "contact",
                                                        "depth_preview")]
    return {"compression": "zstd", "compression_level": 3, "use_dictionary": labels,
            "write_statistics": labels}


def _ordered(jobs: list[Any], make: Callable[[Any], Any], workers: int) -> Iterator[Any]:
    """make(job) for every job, run by `workers` threads at most one job ahead each, yielded in
    job order (so at most 2 x workers batches are in memory)."""
    from collections import deque

    with ThreadPoolExecutor(max(1, workers)) as pool:
        pending: deque[Any] = deque()
        for job in jobs:
            pending.append(pool.submit(make, job))
            if len(pending) > 2 * max(1, workers):
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()


def _fingerprint(ds: VtsDataset, schema: pa.Schema, opts: dict[str, Any], rows: tuple[int, int]
                 ) -> str:
    """sha256 of everything a kind's hub files depend on but their samples: the dataset's
    content, the schema (labels, names, depth unit), the parquet options and rows, this
    version of vtsbench. A finished file is kept by a rerun only when it still matches."""
    import hashlib
    import json

    from .provenance import package_version

    doc = {"dataset_sha256": ds.info.dataset_sha256, "vtsbench": package_version(),
           "schema": hashlib.sha256(schema.serialize().to_pybytes()).hexdigest(),
           "options": repr(sorted(opts.items())), "rows": list(rows)}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()


def _done(state: Path | None, rel: str) -> Path | None:
    """The marker a finished hub file gets in the export's state folder."""
    return None if state is None else state / "done" / (rel.replace("/", "~") + ".json")


def _kept(root: Path, rel: str, marker: Path | None, fp: str) -> dict[str, Any] | None:
    """The marker of a hub file finished by an earlier run with this fingerprint, when the file
    is still there at its size; None otherwise."""
    import json

    if marker is None:
        return None
    try:
        doc = json.loads(marker.read_text())
        ok = (doc["fingerprint"] == fp and (root / rel).stat().st_size == doc["size"]
              and isinstance(doc["sha256"], str))
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return doc if ok else None


def write_failed(e: OSError, path: Path) -> VtsError:
    """One line naming the file being written, for a write that failed (a full disk: pyarrow
    names no file and prints its own detail)."""
    import errno as errnos
    import os

    code = e.errno
    if code is None:  # pyarrow: "... Detail: [errno 28] No space left on device"
        m = re.search(r"\[errno (\d+)\]", str(e), re.IGNORECASE)
        code = int(m.group(1)) if m else None
    reason = os.strerror(code) if code else (str(e).strip().splitlines() or ["write failed"])[0]
    hint = "; the files finished so far are kept for a rerun" \
        if code in (errnos.ENOSPC, errnos.EFBIG, errnos.EDQUOT) else ""
    return VtsError(f"cannot write ({reason}){hint}", path)


def write_kind(ds: VtsDataset, kind: str, root: Path, workers: int = 1,
               advance: Callable[[int], None] | None = None, state: Path | None = None,
               shown: Path | None = None, digests: dict[str, str] | None = None,
               kept: list[str] | None = None) -> list[HubFile]:
    """Write the hub files of one kind under root/hf/<kind>/; returns them in cell order.

    Each file is written through a temporary name and renamed when complete; with a `state`
    folder each finished file then gets a marker there (its fingerprint, size and sha256, which
    go into `digests`), and a rerun keeps the files whose marker still matches (resume, listed
    in `kept`). A
    failed write removes its temporary file and names the file in one line (under `shown`, the
    dataset, rather than root)."""
    import hashlib
    import json

    import pyarrow.parquet as pq

    from ..atomic import TMP_SUFFIX, write_bytes_atomic
    from .provenance import sha256_file

    folder = root / HUB_DIR / kind
    folder.mkdir(parents=True, exist_ok=True)
    view = ds.view(kind)
    schema = arrow_schema(ds.info, kind, extra_columns(view))
    opts = _parquet_options(schema)
    group_rows = _rows_per(view, ROW_GROUP_BYTES, 0.6)
    file_rows = max(group_rows, _rows_per(view, FILE_BYTES, 0.6) // group_rows * group_rows)
    base = _fingerprint(ds, schema, opts, (group_rows, file_rows))
    files: list[tuple[str, int, np.ndarray]] = []  # (path, cell, positions)
    for c, cell in enumerate(cells(ds, kind)):
        for f, start in enumerate(range(0, len(cell.positions), file_rows)):
            files.append((f"{HUB_DIR}/{kind}/{c:03d}-{f:03d}.parquet", c,
                          cell.positions[start:start + file_rows]))
    fps = [hashlib.sha256(f"{base} {rel} ".encode() + pos.astype("<i8").tobytes()).hexdigest()
           for rel, _, pos in files]
    digests = {} if digests is None else digests
    done: dict[int, HubFile] = {}
    for k, (rel, c, pos) in enumerate(files):
        doc = _kept(root, rel, _done(state, rel), fps[k])
        if doc is not None:
            done[k] = HubFile(rel, c, len(pos), doc["size"])
            digests[rel] = doc["sha256"]
            if kept is not None:
                kept.append(rel)
            if advance is not None:
                advance(len(pos))
    keep = {Path(files[k][0]).name for k in done}
    for p in folder.iterdir():  # files of another plan or unfinished, temporaries of a kill
        if p.is_file() and p.name not in keep:
            p.unlink()
    jobs = [(k, pos[g:g + group_rows]) for k, (_, _, pos) in enumerate(files) if k not in done
            for g in range(0, len(pos), group_rows)]
    writer: Any = None
    current = -1

    def tmp_of(k: int) -> Path:
        path = root / files[k][0]
        return path.with_name(f".{path.name}{TMP_SUFFIX}")

    def close() -> None:
        if writer is not None:
            writer.close()
            rel, c, pos = files[current]
            path = root / rel
            tmp_of(current).replace(path)
            size = path.stat().st_size
            done[current] = HubFile(rel, c, len(pos), size)
            digests[rel] = sha256_file(path)
            marker = _done(state, rel)
            if marker is not None:
                marker.parent.mkdir(parents=True, exist_ok=True)
                write_bytes_atomic(marker, json.dumps({"fingerprint": fps[current], "size": size,
                                                       "sha256": digests[rel]}).encode())

    try:
        for k, table in _ordered(jobs, lambda job: (job[0], _batch(
                _view_at(ds, kind, job[1]), schema)), workers):
            try:
                if k != current:
                    close()
                    writer, current = None, k
                    writer = pq.ParquetWriter(tmp_of(k), schema, **opts)
                writer.write_table(table, row_group_size=group_rows)
            except OSError as e:
                raise write_failed(e, (shown or root) / files[current][0]) from None
            if advance is not None:
                advance(table.num_rows)
        try:
            close()
        except OSError as e:
            raise write_failed(e, (shown or root) / files[current][0]) from None
        writer = None
    finally:
        if writer is not None:
            with contextlib.suppress(OSError):
                writer.close()
            tmp_of(current).unlink(missing_ok=True)
    return [done[k] for k in sorted(done)]


def _view_at(ds: VtsDataset, kind: str, positions: np.ndarray) -> View:
    from .loader import View

    return View(ds, kind, positions)


# -- configs -------------------------------------------------------------------------------


def hub_configs(ds: VtsDataset, files: dict[str, list[HubFile]]
                ) -> tuple[dict[str, dict[str, list[str]]], dict[str, str]]:
    """Per config (`<kind>_all` and one per scheme), split -> the files of its samples."""
    configs: dict[str, dict[str, list[str]]] = {}
    kinds: dict[str, str] = {}
    for kind in ("slip", "static"):
        if not files.get(kind):
            continue
        cell_list = cells(ds, kind)
        schemes = schemes_of(ds, kind)
        for j, scheme in enumerate(schemes):
            name = config_name(kind, scheme)
            configs[name], kinds[name] = {}, kind
            for part in ds.parts(scheme):
                keep = {c for c, cell in enumerate(cell_list) if cell.parts[j] == part}
                configs[name][split_name(part)] = [f.path for f in files[kind] if f.cell in keep]
        configs[f"{kind}_all"] = {"full": [f.path for f in files[kind]]}
        kinds[f"{kind}_all"] = kind
    return configs, kinds


# -- export --------------------------------------------------------------------------------


@dataclass
class ExportResult:
    """What export_hf wrote, for the command's summary."""

    layout: HubLayout
    seconds: float
    kept: int = 0  # parquet files kept from an interrupted export


#: The export's state folder inside its stage: a marker per finished parquet file.
EXPORT_WORK = ".export"


def export_stage(root: Path) -> Path:
    """The hidden folder beside a dataset where export-hf makes its next version:
    `.DATASET.hf.partial`."""
    return root.with_name(f".{root.name}.hf.partial")


def _link_dataset(root: Path, stage: Path) -> None:
    """Make the stage the dataset without its hub copy, card and info.json: every other file
    hard-linked (copied where the filesystem has no links), so no data is copied; the stage's
    own hub files and state are kept for the resume."""
    import os
    import shutil

    for p in stage.iterdir():
        if p.name not in (HUB_DIR, EXPORT_WORK):
            shutil.rmtree(p) if p.is_dir() and not p.is_symlink() else p.unlink()
    for dirpath, dirnames, filenames in os.walk(root):
        here = Path(dirpath)
        rel_dir = here.relative_to(root)
        if rel_dir == Path("."):
            dirnames[:] = [d for d in dirnames if d != HUB_DIR]
        (stage / rel_dir).mkdir(parents=True, exist_ok=True)
        for name in [*filenames, *(d for d in dirnames if (here / d).is_symlink())]:
            src, dst = here / name, stage / rel_dir / name
            if (rel_dir / name).as_posix() in ("README.md", INFO_PATH):
                continue
            if src.is_symlink():
                os.symlink(os.readlink(src), dst)
                continue
            try:
                os.link(src, dst)
            except OSError:
                shutil.copy2(src, dst)
        dirnames[:] = [d for d in dirnames if not (here / d).is_symlink()]


def export_hf(dataset: str | Path, *, workers: int = 1, license: str = "unknown",
              progress: bool = False) -> ExportResult:
    """Write the hub copy of a built dataset into it (hf/, a new README.md) and record the new
    files in meta/info.json, so `vtsbench verify` still checks every file.

    The dataset is never half exported: its next version is made beside it, in
    `.DATASET.hf.partial` (its files hard-linked, the parquet files written there one by one,
    each through a temporary name and marked done, then the card and info.json), and swapped
    in as a whole by the same rename as `build --overwrite` (staging.commit). At every kill
    point DATASET is the previous complete dataset or the new one, and a rerun keeps the
    parquet files already finished (those whose dataset and schema have not changed).
    """
    import os
    import shutil
    import time

    from ..atomic import write_bytes_atomic
    from .card import write_hub_card
    from .finish import hash_files
    from .loader import load
    from .staging import commit, locked_stage, recover

    t0 = time.perf_counter()
    if not re.fullmatch(r"[a-z0-9][a-z0-9.+-]{0,63}", license):
        raise VtsError(f"license must be a Hub license id (lower case, e.g. cc-by-4.0, mit, "
                       f"other), got {license!r}")
    given = Path(dataset)
    root = given.resolve()
    recover(root, export_stage(root), EXPORT_WORK)  # a killed export or build: put right
    ds = load(given)
    if ds.loc.remote:
        raise VtsError("export-hf writes into the dataset: give a local folder", given)
    if not os.access(root.parent, os.W_OK):
        raise VtsError(f"export-hf makes the new version beside the dataset (in "
                       f"{export_stage(root).name}), and this folder is not writable",
                       root.parent)
    with locked_stage(root, export_stage(root), EXPORT_WORK) as stage:
        _link_dataset(root, stage)
        files: dict[str, list[HubFile]] = {}
        digests: dict[str, str] = {}
        kept: list[str] = []
        total = sum(len(ds.view(k)) for k in KINDS)
        with _progress(progress, total) as advance:
            for kind in KINDS:
                if len(ds.view(kind)):
                    files[kind] = write_kind(ds, kind, stage, workers, advance,
                                             stage / EXPORT_WORK, given, digests, kept)
                else:
                    shutil.rmtree(stage / HUB_DIR / kind, ignore_errors=True)
        configs, kinds = hub_configs(ds, files)
        layout = HubLayout(files, configs, kinds)
        write_hub_card(stage, ds, layout, license)
        info = ds.info
        keep = {k: v for k, v in info.files.items()
                if not k.startswith(f"{HUB_DIR}/") and k != "README.md"}
        new = hash_files(stage, lambda rel: rel.startswith(f"{HUB_DIR}/") or rel == "README.md",
                         digests)
        info.files = dict(sorted({**keep, **new}.items()))
        write_bytes_atomic(stage / INFO_PATH, info.to_json().encode())
        commit(stage, root, EXPORT_WORK)
    return ExportResult(layout, time.perf_counter() - t0, len(kept))


class _progress:
    """A rich progress bar of samples written (a no-op callable when off)."""

    def __init__(self, on: bool, total: int) -> None:
        self.on, self.total = on, total
        self.bar: Any = None

    def __enter__(self) -> Callable[[int], None]:
        if not self.on:
            return lambda _n: None
        from ..progress import progress_bar

        self.bar = progress_bar()
        self.bar.__enter__()
        task = self.bar.add_task("samples", total=self.total)
        return lambda n: self.bar.advance(task, n)

    def __exit__(self, *exc: Any) -> None:
        if self.bar is not None:
            self.bar.__exit__(*exc)
