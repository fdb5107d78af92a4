"""The dataset's typed records (index rows, samples, info.json, split files) and their schemas.

Every class mirrors a JSON Schema in `schemas/` (sample, dataset_info, split), and a test keeps
the two in step. `load_info` validates `meta/info.json` and raises a one-line `VtsError`.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import VtsError
from ..labels import STATES
from .location import INFO_PATH

if TYPE_CHECKING:
    import pyarrow

FORMAT = "vtsbench.dataset"
#: 1.1: info.json carries info_sha256, the sha256 of its own text (see `DatasetInfo.to_json`),
#: and the depth array CF attributes (scale_factor, units) that xarray and other readers decode.
FORMAT_VERSION = "1.1"
DEPTH_SCALE_MM = 0.001
DEPTH_DTYPE = "int16"
KINDS = ("static", "slip")
SCHEMA_DIR = Path(__file__).resolve().parent.parent / "schemas"
SCHEMA_NAMES = ("sample", "dataset_info", "split")
DEFAULT_UNITS: dict[str, str] = {
    "depth": "mm",
    "length": "mm",
    "pixel_frame": "x along the columns, y down the rows",
    "motion_frame": "image, x right, y up",
    "direction": "class k covers [45k - 22.5, 45k + 22.5) degrees counter-clockwise from +x",
}
#: Index columns in table order; the static index omits SLIP_ONLY.
INDEX_COLUMNS = ("sample_id", "row", "object", "class_idx", "session", "sensor", "mm_per_px_x",
                 "mm_per_px_y", "press_depth_mm", "contact_x_px", "contact_y_px", "state",
                 "state_idx", "direction", "motion_dx_mm", "motion_dy_mm", "source")
SLIP_ONLY = ("state", "state_idx", "direction", "motion_dx_mm", "motion_dy_mm")
#: The arrays of a dataset, and of one built without depth (`vtsbench build --no-depth`).
ARRAYS = ("rgb", "depth", "contact")
RGB_ONLY = ("rgb",)


@lru_cache(maxsize=len(SCHEMA_NAMES))
def schema(name: str) -> dict[str, Any]:
    """One of the dataset JSON Schemas shipped with the package: sample, dataset_info, split."""
    if name not in SCHEMA_NAMES:
        raise ValueError(f"unknown schema {name!r}; expected one of {SCHEMA_NAMES}")
    return json.loads((SCHEMA_DIR / f"{name}.schema.json").read_text())


def schema_errors(doc: Any, name: str, at: str = "") -> list[str]:
    """Every violation of schema `name` by doc (or by its `$defs` entry `at`), one line each."""
    sch = schema(name)
    if at:
        sch = {"$schema": sch["$schema"], "$defs": sch["$defs"], "$ref": f"#/$defs/{at}"}
    return _violations(sch, doc)


def _violations(sch: dict[str, Any], doc: Any) -> list[str]:
    import jsonschema

    from ..jsonio import strict_validator

    validator = strict_validator(sch)
    out = []
    for err in sorted(validator.iter_errors(doc), key=lambda e: list(map(str, e.absolute_path))):
        where = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in err.absolute_path)
        best = jsonschema.exceptions.best_match([err]) if err.context else err
        out.append(f"{where.lstrip('.') or '(top level)'}: {best.message}")
    return out


def _pair(v: Any) -> tuple[float, float] | None:
    return None if v is None else (float(v[0]), float(v[1]))


@dataclass(frozen=True)
class SampleMeta:
    """One index row (a static frame or a slip sequence); slip-only labels are None for static.

    `state_idx` is filled from `state` when left None.
    """

    sample_id: str
    kind: str
    row: int
    object: str
    class_idx: int
    session: str
    sensor: str
    mm_per_px_x: float | None  # None only when the scale is unknown (built without depth)
    mm_per_px_y: float | None
    source: str
    press_depth_mm: float | None = None
    contact_x_px: float | None = None
    contact_y_px: float | None = None
    state: str | None = None
    state_idx: int | None = None
    direction: int | None = None
    motion_dx_mm: float | None = None
    motion_dy_mm: float | None = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"{self.sample_id}: kind must be one of {KINDS}, got {self.kind!r}")
        if self.state is not None and self.state not in STATES:
            raise ValueError(f"{self.sample_id}: unknown state {self.state!r}")
        want = None if self.state is None else STATES.index(self.state)
        if self.state_idx is None and want is not None:
            object.__setattr__(self, "state_idx", want)
        elif self.state_idx != want:
            raise ValueError(f"{self.sample_id}: state_idx {self.state_idx} does not match "
                             f"state {self.state!r}")

    def to_row(self) -> dict[str, Any]:
        """The index row: columns in table order, without the slip-only ones for static."""
        cols = INDEX_COLUMNS if self.kind == "slip" else _static_columns()
        return {c: getattr(self, c) for c in cols}

    def to_dict(self) -> dict[str, Any]:
        """Every field, nulls included ($defs/index_row of the sample schema)."""
        return {k: getattr(self, k) for k in self.__dataclass_fields__}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> SampleMeta:
        return cls(**{k: d.get(k) for k in cls.__dataclass_fields__})

    @classmethod
    def from_row(cls, row: Mapping[str, Any], kind: str) -> SampleMeta:
        """A row read from index/<kind>.parquet (slip-only columns absent for static)."""
        return cls.from_dict({**row, "kind": kind})


def _static_columns() -> tuple[str, ...]:
    return tuple(c for c in INDEX_COLUMNS if c not in SLIP_ONLY)


def index_schema(kind: str, scale_known: bool = True) -> pyarrow.Schema:
    """The pyarrow schema of index/<kind>.parquet (docs/dataset.md, Index columns).

    scale_known=False: mm_per_px_x and mm_per_px_y may be null, in a dataset built without
    depth from sessions whose scale is unknown (every other dataset has them).
    """
    import pyarrow as pa

    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    types = {"sample_id": pa.string(), "row": pa.int64(), "object": pa.string(),
             "class_idx": pa.int32(), "session": pa.string(), "sensor": pa.string(),
             "mm_per_px_x": pa.float64(), "mm_per_px_y": pa.float64(),
             "press_depth_mm": pa.float64(), "contact_x_px": pa.float64(),
             "contact_y_px": pa.float64(), "state": pa.string(), "state_idx": pa.int32(),
             "direction": pa.int32(), "motion_dx_mm": pa.float64(), "motion_dy_mm": pa.float64(),
             "source": pa.string()}
    nullable = {"press_depth_mm", "contact_x_px", "contact_y_px", *SLIP_ONLY}
    if not scale_known:
        nullable |= {"mm_per_px_x", "mm_per_px_y"}
    cols = INDEX_COLUMNS if kind == "slip" else _static_columns()
    return pa.schema([pa.field(c, types[c], nullable=c in nullable) for c in cols])


def index_schema_of(table_schema: pyarrow.Schema, kind: str) -> pyarrow.Schema | None:
    """The index schema (either scale variant) a read table has, or None if neither.

    The fixed columns may be followed by extra nullable string columns: the recordings' own
    fields (pattern fields, `take`, keys of an entry's meta), see `extra_column_name`."""
    import pyarrow as pa

    have = table_schema.remove_metadata()
    for known in (True, False):
        want = index_schema(kind, known)
        n = len(want)
        if len(have) < n or not pa.schema(list(have)[:n]).equals(want):
            continue
        extra = list(have)[n:]
        if all(f.type == pa.string() and f.nullable and EXTRA_NAME_RE.match(f.name)
               and f.name not in INDEX_COLUMNS for f in extra):
            return have
    return None


#: An extra index column's name: a lowercase identifier (the field's name, cleaned).
EXTRA_NAME_RE = re.compile(r"^[a-z_][a-z0-9_]{0,63}$")


def extra_column_name(key: str) -> str | None:
    """The index column for a recording's own field or meta key: lowercased, other characters
    as '_', prefixed `meta_` where it would shadow a fixed column; None if nothing is left."""
    name = re.sub(r"[^a-z0-9_]+", "_", str(key).strip().lower()).strip("_")[:58]
    if not name:
        return None
    if name[0].isdigit() or name in INDEX_COLUMNS or name in ("kind", "labels", "meta"):
        name = f"meta_{name}"
    return name if EXTRA_NAME_RE.match(name) else None


@dataclass(frozen=True)
class ArraySpec:
    """An array of a loaded sample by dtype and shape; depth also names its unit and scale."""

    dtype: str
    shape: tuple[int, ...]
    unit: str | None = None
    depth_scale_mm: float | None = None

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"dtype": self.dtype, "shape": list(self.shape)}
        if self.unit is not None:
            d["unit"] = self.unit
        if self.depth_scale_mm is not None:
            d["depth_scale_mm"] = self.depth_scale_mm
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ArraySpec:
        return cls(d["dtype"], tuple(int(x) for x in d["shape"]), d.get("unit"),
                   d.get("depth_scale_mm"))


@dataclass(frozen=True)
class Sample:
    """What a loaded sample holds, arrays described by ArraySpec (schemas/sample.schema.json).

    A sample of a dataset built without depth (RGB_ONLY) has no depth and no contact (None
    here, absent from to_dict), and mm_per_px is None when its session gives no scale."""

    sample_id: str
    kind: str
    object: str
    class_idx: int
    session: str
    sensor: str
    mm_per_px: tuple[float, float] | None
    rgb: ArraySpec
    depth: ArraySpec | None
    contact: ArraySpec | None
    source: str
    press_depth_mm: float | None = None
    contact_px: tuple[float, float] | None = None
    state: str | None = None
    state_idx: int | None = None
    direction: int | None = None
    motion_mm: tuple[float, float] | None = None

    @classmethod
    def from_meta(cls, m: SampleMeta, resolution: tuple[int, int], frames: int | None = None,
                  depth_dtype: str = DEPTH_DTYPE, depth_scale_mm: float = DEPTH_SCALE_MM,
                  arrays: tuple[str, ...] = ARRAYS) -> Sample:
        """The description of index row m as stored: frames (T) is required for slip samples;
        arrays: the dataset's (info.arrays), RGB_ONLY for a build without depth."""
        if m.kind == "slip" and not frames:
            raise ValueError("a slip sample needs frames (T)")
        if tuple(arrays) not in (ARRAYS, RGB_ONLY):
            raise ValueError(f"arrays must be {ARRAYS} or {RGB_ONLY}, got {tuple(arrays)}")
        depth = tuple(arrays) == ARRAYS
        lead = (frames,) if m.kind == "slip" else ()
        hw = (*lead, int(resolution[0]), int(resolution[1]))
        xy = (m.contact_x_px, m.contact_y_px)
        dxy = (m.motion_dx_mm, m.motion_dy_mm)
        scale = (m.mm_per_px_x, m.mm_per_px_y)
        return cls(m.sample_id, m.kind, m.object, m.class_idx, m.session, m.sensor,
                   None if None in scale else _pair(scale), ArraySpec("uint8", (*hw, 3)),
                   ArraySpec(depth_dtype, hw, "mm", depth_scale_mm) if depth else None,
                   ArraySpec("bool", hw) if depth else None,
                   m.source, m.press_depth_mm, None if None in xy else _pair(xy), m.state,
                   m.state_idx, m.direction, None if None in dxy else _pair(dxy))

    def to_dict(self) -> dict[str, Any]:
        """The schema's document: depth and contact absent (not null) without depth."""
        d: dict[str, Any] = {}
        for k in self.__dataclass_fields__:
            v = getattr(self, k)
            if v is None and k in ("depth", "contact"):
                continue
            d[k] = v.to_dict() if isinstance(v, ArraySpec) else list(v) if isinstance(
                v, tuple) else v
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Sample:
        args = {k: d.get(k) for k in cls.__dataclass_fields__}
        for k in ("rgb", "depth", "contact"):
            args[k] = None if d.get(k) is None and k != "rgb" else ArraySpec.from_dict(d[k])
        for k in ("mm_per_px", "contact_px", "motion_mm"):
            args[k] = _pair(args[k])
        return cls(**args)


@dataclass(frozen=True)
class KindCounts:
    """Samples of one kind in total and per object, session, state and direction."""

    samples: int = 0
    objects: dict[str, int] = field(default_factory=dict)
    sessions: dict[str, int] = field(default_factory=dict)
    states: dict[str, int] = field(default_factory=dict)
    directions: dict[str, int] = field(default_factory=dict)

    @classmethod
    def of(cls, samples: Iterable[SampleMeta]) -> KindCounts:
        """Count samples (all of one kind); states and directions only for slip samples."""
        def tally(keys: Iterable[str]) -> dict[str, int]:
            out: dict[str, int] = {}
            for k in keys:
                out[k] = out.get(k, 0) + 1
            return dict(sorted(out.items()))

        ss = list(samples)
        slip = [s for s in ss if s.kind == "slip"]
        return cls(len(ss), tally(s.object for s in ss), tally(s.session for s in ss),
                   tally(s.state or "unknown" for s in slip),
                   tally("unknown" if s.direction is None else str(s.direction)
                         for s in slip if s.state == "slip"))

    def to_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> KindCounts:
        return cls(int(d["samples"]), *(dict(d[k]) for k in
                                        ("objects", "sessions", "states", "directions")))


@dataclass(frozen=True)
class Counts:
    """Counts per kind, and per part of every split."""

    static: KindCounts = field(default_factory=KindCounts)
    slip: KindCounts = field(default_factory=KindCounts)
    splits: dict[str, dict[str, int]] = field(default_factory=dict)

    @classmethod
    def of(cls, samples: Iterable[SampleMeta], splits: Iterable[SplitFile] = ()) -> Counts:
        ss = list(samples)
        return cls(KindCounts.of(s for s in ss if s.kind == "static"),
                   KindCounts.of(s for s in ss if s.kind == "slip"),
                   {sp.name: {p: len(ids) for p, ids in sp.parts.items()} for sp in splits})

    def to_dict(self) -> dict[str, Any]:
        return {"static": self.static.to_dict(), "slip": self.slip.to_dict(),
                "splits": {k: dict(v) for k, v in self.splits.items()}}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Counts:
        return cls(KindCounts.from_dict(d["static"]), KindCounts.from_dict(d["slip"]),
                   {k: dict(v) for k, v in d["splits"].items()})


@dataclass(frozen=True)
class ZarrSettings:
    """How the arrays are stored: compressor, its level, whole samples per shard per kind."""

    samples_per_shard: dict[str, int]
    compressor: str = "zstd"
    level: int = 3

    def to_dict(self) -> dict[str, Any]:
        return {"compressor": self.compressor, "level": self.level,
                "samples_per_shard": dict(self.samples_per_shard)}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ZarrSettings:
        return cls(dict(d["samples_per_shard"]), d["compressor"], int(d["level"]))


@dataclass(frozen=True)
class Calibration:
    """The calibration that made the depth: sensor, method, sha256 of its file."""

    sensor: str
    method: str
    sha256: str

    def to_dict(self) -> dict[str, str]:
        return {"sensor": self.sensor, "method": self.method, "sha256": self.sha256}


@dataclass
class DatasetInfo:
    """meta/info.json: versions, units, shapes, counts, build parameters and file checksums."""

    name: str
    vtsbench_version: str
    frames_per_sequence: int
    resolution: tuple[int, int]  # (height, width)
    objects: list[str]
    counts: Counts
    shapes: dict[str, dict[str, tuple[int, ...]]]
    zarr: ZarrSettings
    dataset_version: str = "1.0.0"
    created_by: str = ""
    calibration: Calibration | None = None
    splits: dict[str, str] = field(default_factory=dict)
    files: dict[str, str] = field(default_factory=dict)
    dataset_sha256: str = ""
    build: dict[str, Any] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=lambda: dict(DEFAULT_UNITS))
    depth_scale_mm: float = DEPTH_SCALE_MM
    depth_dtype: str = DEPTH_DTYPE
    format_version: str = FORMAT_VERSION
    #: as read from the file (to_json computes it afresh)
    info_sha256: str = field(default="", compare=False)

    def class_idx(self, obj: str) -> int:
        """The class index of an object name (its index in the sorted `objects`)."""
        return self.objects.index(obj)

    @property
    def arrays(self) -> tuple[str, ...]:
        """The arrays the dataset holds: rgb, depth and contact, or rgb alone (built with
        --no-depth), in that order."""
        names = {a for shapes in self.shapes.values() for a in shapes}
        return tuple(a for a in ARRAYS if a in names)

    @property
    def has_depth(self) -> bool:
        """False for a dataset built without depth (rgb only)."""
        return "depth" in self.arrays

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": FORMAT, "format_version": self.format_version,
            "dataset_version": self.dataset_version, "name": self.name,
            "created_by": self.created_by, "vtsbench_version": self.vtsbench_version,
            "units": dict(self.units), "depth_scale_mm": self.depth_scale_mm,
            "depth_dtype": self.depth_dtype, "frames_per_sequence": self.frames_per_sequence,
            "resolution": list(self.resolution), "objects": list(self.objects),
            "counts": self.counts.to_dict(),
            "shapes": {k: {a: list(s) for a, s in v.items()} for k, v in self.shapes.items()},
            "zarr": self.zarr.to_dict(),
            "calibration": None if self.calibration is None else self.calibration.to_dict(),
            "splits": dict(self.splits), "files": dict(sorted(self.files.items())),
            "dataset_sha256": self.dataset_sha256, "build": dict(self.build),
        }

    def to_json(self) -> str:
        """The text of meta/info.json. From format 1.1 its last key, info_sha256, is the sha256
        of the text with that value empty: a change of any byte of the file is detected, while
        the files list cannot hold the checksum of the file that holds it."""
        doc = self.to_dict()
        if _minor(self.format_version) < 1:
            return json.dumps(doc, indent=1, allow_nan=False) + "\n"
        doc[INFO_HASH] = ""
        text = json.dumps(doc, indent=1, allow_nan=False) + "\n"
        return _with_info_hash(text, hashlib.sha256(text.encode()).hexdigest())

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> DatasetInfo:
        c = d.get("calibration")
        return cls(
            name=d["name"], vtsbench_version=d["vtsbench_version"],
            frames_per_sequence=int(d["frames_per_sequence"]),
            resolution=(int(d["resolution"][0]), int(d["resolution"][1])),
            objects=list(d["objects"]), counts=Counts.from_dict(d["counts"]),
            shapes={k: {a: tuple(int(x) for x in s) for a, s in v.items()}
                    for k, v in d["shapes"].items()},
            zarr=ZarrSettings.from_dict(d["zarr"]), dataset_version=d["dataset_version"],
            created_by=d.get("created_by", ""),
            calibration=None if c is None else Calibration(c["sensor"], c["method"],
                                                           c["sha256"]),
            splits=dict(d["splits"]), files=dict(d["files"]),
            dataset_sha256=d["dataset_sha256"], build=dict(d["build"]), units=dict(d["units"]),
            depth_scale_mm=float(d["depth_scale_mm"]), depth_dtype=d["depth_dtype"],
            format_version=d["format_version"], info_sha256=d.get("info_sha256", ""))


INFO_HASH = "info_sha256"


def _minor(version: str) -> int:
    """The minor number of a format version such as '1.1' (0 when unreadable)."""
    m = re.fullmatch(r"\d+\.(\d+)", str(version))
    return int(m.group(1)) if m else 0


def _with_info_hash(text: str, value: str) -> str:
    """info.json text with its (last) info_sha256 value replaced."""
    key = f'"{INFO_HASH}": "'
    i = text.rfind(key)
    j = text.index('"', i + len(key))
    return text[:i + len(key)] + value + text[j:]


def info_hash_problem(text: str, doc: Mapping[str, Any]) -> str | None:
    """Why info.json's text does not match its info_sha256 (None when it does, or for format
    1.0, which has none)."""
    if _minor(str(doc.get("format_version", ""))) < 1:
        return None
    got = doc.get(INFO_HASH)
    if not isinstance(got, str) or f'"{INFO_HASH}": "{got}"' not in text:
        return f"{INFO_HASH} missing (format 1.1 and later carry it)"
    want = hashlib.sha256(_with_info_hash(text, "").encode()).hexdigest()
    if got != want:
        return (f"{INFO_HASH} mismatch: the file was changed after the build (its text hashes "
                f"to {want[:16]}..., it records {got[:16]}...)")
    return None


def consistency_problems(info: DatasetInfo) -> list[str]:
    """Where info.json contradicts itself: shapes against resolution and frames_per_sequence,
    shapes against counts."""
    out = []
    h, w = info.resolution
    for kind, shapes in info.shapes.items():
        for name, shape in shapes.items():
            hw = shape[-3:-1] if name == "rgb" else shape[-2:]
            if tuple(hw) != (h, w):
                out.append(f"shapes.{kind}.{name} {list(shape)} contradicts resolution {h}x{w}")
            if kind == "slip" and len(shape) > 1 and shape[1] != info.frames_per_sequence:
                out.append(f"shapes.slip.{name} {list(shape)} contradicts frames_per_sequence "
                           f"{info.frames_per_sequence}")
        n = shapes.get("rgb", (0,))[0]
        if any(s[0] != n for s in shapes.values()):
            out.append(f"shapes.{kind}: arrays of different lengths")
        total = getattr(info.counts, kind).samples if hasattr(info.counts, kind) else n
        if total != n:
            out.append(f"counts.{kind}.total {total} contradicts shapes.{kind} ({n} samples)")
    return out


#: A split name: the split schema's `name` (it is also the file name under meta/splits/).
SPLIT_NAME = re.compile(r"[a-z0-9][a-z0-9_]{0,63}")


def _shown(values: Iterable[str], n: int = 3) -> str:
    vs = list(values)
    return ", ".join(repr(v if len(v) <= 60 else v[:60] + "...") for v in vs[:n]) + (
        ", ..." if len(vs) > n else "")


def info_problems(info: DatasetInfo) -> list[str]:
    """Where info.json names what it may not: a split that is no plain name (its file would be
    read from elsewhere), a file outside the dataset, counts of splits it does not list."""
    out = []
    bad = [n for n in info.splits if not SPLIT_NAME.fullmatch(n)]
    if bad:
        out.append(f"splits: {len(bad)} name(s) that are not plain split names (a-z, 0-9 and _, "
                   f"at most 64): {_shown(bad)}")
    paths = [p for p in info.files
             if p.startswith("/") or any(s in ("", ".", "..") for s in p.split("/"))]
    if paths:
        out.append(f"files: {len(paths)} path(s) outside the dataset folder: {_shown(paths)}")
    if set(info.counts.splits) != set(info.splits):
        out.append(f"counts.splits names {_shown(sorted(info.counts.splits))}, splits "
                   f"{_shown(sorted(info.splits))}")
    return out


def dataset_checksum(files: Mapping[str, str]) -> str:
    """dataset_sha256: sha256 of the lines `path sha256\\n`, sorted by path, of every file under
    data/, index/ and meta/splits/ (UTF-8)."""
    keep = sorted(p for p in files if p.startswith(("data/", "index/", "meta/splits/")))
    return hashlib.sha256("".join(f"{p} {files[p]}\n" for p in keep).encode()).hexdigest()


def _rgb_only(doc: Any) -> bool:
    """Whether an info document describes a dataset of rgb arrays alone (--no-depth)."""
    shapes = doc.get("shapes") if isinstance(doc, dict) else None
    return (isinstance(shapes, dict) and bool(shapes)
            and all(isinstance(v, dict) and set(v) == set(RGB_ONLY) for v in shapes.values()))


def info_schema_errors(doc: Any) -> list[str]:
    """schema_errors(doc, "dataset_info"), where a dataset built without depth (every kind's
    shapes hold rgb alone, and no calibration) is valid too."""
    errs = schema_errors(doc, "dataset_info")
    if _rgb_only(doc) and doc.get("calibration") is not None:
        errs.append("calibration: a dataset without depth has none (null)")
    return errs


def load_info(path: str | Path) -> DatasetInfo:
    """Read and validate meta/info.json (given the file or the dataset folder)."""
    path = Path(path)
    if path.is_dir() and not path.as_posix().endswith(INFO_PATH):  # (info.json itself a
        # folder is said so below)
        path = path / INFO_PATH
    if not path.exists() and not path.is_symlink():
        raise VtsError("not found (not a vtsbench dataset?)", path)
    from ..jsonio import loads, read_bytes

    data = read_bytes(path, "dataset info", 64 << 20)
    doc = loads(data, path)
    problem = info_hash_problem(data.decode("utf-8"), doc) if isinstance(doc, dict) else None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        got = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
        raise VtsError(f"not a vtsbench dataset info (format is {got!r}, expected {FORMAT!r})",
                       path)
    version = doc.get("format_version")
    major = FORMAT_VERSION.split(".")[0]
    if isinstance(version, str) and re.fullmatch(r"\d+\.\d+", version) and (
            version.split(".")[0] != major):
        raise VtsError(f"format_version {version!r} is not one this vtsbench reads "
                       f"({major}.x); use a matching vtsbench", path)
    errs = info_schema_errors(doc)
    if errs:
        more = f" (and {len(errs) - 1} more)" if len(errs) > 1 else ""
        raise VtsError(f"{errs[0]}{more}", path)
    if doc["objects"] != sorted(doc["objects"]):
        raise VtsError("objects: not sorted (class_idx is the index in the sorted names)", path)
    if problem:
        raise VtsError(problem, path)
    info = DatasetInfo.from_dict(doc)
    bad = consistency_problems(info) + info_problems(info)
    if bad:
        more = f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""
        raise VtsError(f"{bad[0]}{more}", path)
    return info


@dataclass
class SplitFile:
    """meta/splits/<name>.json: the sorted sample ids of every part of one split scheme.

    `disjoint` rules: "KEY" means no two parts share a value of KEY; "KEY:PART" means PART
    shares no value of KEY with any other part (KEY: object, session, location).
    """

    name: str
    kind: str
    description: str
    seed: int
    parts: dict[str, list[str]]
    disjoint: list[str] = field(default_factory=list)
    params: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.parts = {p: sorted(ids) for p, ids in self.parts.items()}

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "kind": self.kind, "description": self.description,
                "seed": self.seed, "parts": {p: list(v) for p, v in self.parts.items()},
                "disjoint": list(self.disjoint), "params": self.params}

    def to_json(self) -> str:
        """Canonical JSON: sorted keys, indent 1, ASCII only, no NaN, one trailing newline."""
        return json.dumps(self.to_dict(), sort_keys=True, indent=1, ensure_ascii=True,
                          allow_nan=False) + "\n"

    def to_bytes(self) -> bytes:
        return self.to_json().encode("ascii")

    def sha256(self) -> str:
        """sha256 of the canonical JSON bytes, which are also the bytes of the split's file."""
        return hashlib.sha256(self.to_bytes()).hexdigest()

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> SplitFile:
        return cls(d["name"], d["kind"], d["description"], int(d["seed"]),
                   {p: list(v) for p, v in d["parts"].items()}, list(d["disjoint"]),
                   dict(d["params"]))
