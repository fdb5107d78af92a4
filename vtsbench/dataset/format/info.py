"""meta/info.json as typed records (DatasetInfo and its parts), its own checksum, and the
checks of it beyond its JSON Schema; `load_info` validates the file in one-line VtsErrors."""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ...errors import VtsError
from .episode_video import codec_from_dict
from .layout import ARRAYS, CHECKSUMMED, DEPTH_DTYPE, DEPTH_SCALE_MM, INFO_PATH, KINDS, RGB_ONLY
from .problems import first
from .records import SPLIT_NAME, SampleMeta, SplitFile, schema_errors
from .video import VideoCodec

FORMAT = "vtsbench.dataset"
#: 1.1: info.json carries info_sha256, the sha256 of its own text (see `DatasetInfo.to_json`),
#: and the depth array CF attributes (scale_factor, units) that xarray and other readers decode.
FORMAT_VERSION = "1.1"
#: 1.2: episodes (continuous takes stored once, format/episodes.py), counted under `episodes`.
#: Written only by a dataset that holds episodes, so builds without them keep their bytes.
EPISODES_FORMAT_VERSION = "1.2"
#: 1.3: the static frames and slip sequences stored as views of the episode store
#: (`"sample_storage": "episodes"`): each sample's index row names its episode and the store
#: row of its first frame (format/index.py VIEW_COLUMNS); no data/static.zarr or slip.zarr.
VIEWS_FORMAT_VERSION = "1.3"
#: info.json `sample_storage` of a dataset whose samples are views of its episode store.
SAMPLE_STORAGE_EPISODES = "episodes"
SAMPLE_STORAGES = (SAMPLE_STORAGE_EPISODES,)
DEFAULT_UNITS: dict[str, str] = {
    "depth": "mm",
    "length": "mm",
    "pixel_frame": "x along the columns, y down the rows",
    "motion_frame": "image, x right, y up",
    "direction": "class k covers [45k - 22.5, 45k + 22.5) degrees counter-clockwise from +x",
}
INFO_HASH = "info_sha256"


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
class EpisodeCounts:
    """Episodes (format 1.2): how many, their frames, episodes per object and session, frames
    per state ('unknown' for null) and frames missing from the takes (timestamp gaps); and,
    when the episodes' RGB is stored as video (format/episode_video.py), the codec's
    settings (not a count: None, and no key, when the RGB is in Zarr)."""

    episodes: int = 0
    frames: int = 0
    objects: dict[str, int] = field(default_factory=dict)
    sessions: dict[str, int] = field(default_factory=dict)
    states: dict[str, int] = field(default_factory=dict)
    dropped_frames: int = 0
    video: VideoCodec | None = None

    def to_dict(self) -> dict[str, Any]:
        doc = {k: getattr(self, k) for k in COUNT_FIELDS}
        if self.video is not None:  # written only when set: other datasets keep their bytes
            doc[VIDEO_FIELD] = self.video.to_dict()
        return doc

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> EpisodeCounts:
        """The block as info.json holds it (checked by its schema: `$defs/video_codec` admits
        only codecs vtsbench reads)."""
        video = d.get(VIDEO_FIELD)
        return cls(int(d["episodes"]), int(d["frames"]), dict(d["objects"]),
                   dict(d["sessions"]), dict(d["states"]), int(d["dropped_frames"]),
                   None if video is None else codec_from_dict(video))

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickled as its info.json block (a DataLoader worker gets the dataset's info; the
        codec's read-only options mapping does not pickle)."""
        return (EpisodeCounts.from_dict, (self.to_dict(),))


#: The counts of EpisodeCounts (what the episode indexes must agree with), in info.json order.
COUNT_FIELDS = ("episodes", "frames", "objects", "sessions", "states", "dropped_frames")
#: The key of info.json's `episodes` block recording the codec of an RGB stored as video.
VIDEO_FIELD = "video"


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
    #: format 1.2, a dataset holding episodes: their counts (None, and no key, otherwise)
    episodes: EpisodeCounts | None = None
    #: format 1.3: "episodes" when the static and slip samples are views of the episode store
    #: (None, and no key, otherwise)
    sample_storage: str | None = None
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
    def views(self) -> bool:
        """Whether the static and slip samples are views of the episode store (format 1.3)."""
        return self.sample_storage == SAMPLE_STORAGE_EPISODES

    @property
    def has_depth(self) -> bool:
        """False for a dataset built without depth (rgb only)."""
        return "depth" in self.arrays

    def to_dict(self) -> dict[str, Any]:
        doc = {
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
        if self.episodes is not None:  # format 1.2 only: other datasets keep their bytes
            doc["episodes"] = self.episodes.to_dict()
        if self.sample_storage is not None:  # format 1.3 only, as episodes
            doc["sample_storage"] = self.sample_storage
        return doc

    def to_json(self) -> str:
        """The text of meta/info.json. From format 1.1 its last key, info_sha256, is the sha256
        of the text with that value empty: a change of any byte of the file is detected, while
        the files list cannot hold the checksum of the file that holds it."""
        doc = self.to_dict()
        if format_minor(self.format_version) < 1:
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
            format_version=d["format_version"], info_sha256=d.get("info_sha256", ""),
            episodes=None if d.get("episodes") is None else EpisodeCounts.from_dict(
                d["episodes"]), sample_storage=d.get("sample_storage"))


def format_minor(version: str) -> int:
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
    if format_minor(str(doc.get("format_version", ""))) < 1:
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
    ep, frames = info.episodes, info.shapes.get("episodes", {}).get("rgb", (None,))[0]
    if (ep is None) != (frames is None) or (ep is not None and ep.frames != frames):
        out.append(f"episodes {'absent' if ep is None else f'{ep.frames} frames'} contradicts "
                   f"shapes.episodes ({'absent' if frames is None else f'{frames} frames'})")
    if ep is not None and format_minor(info.format_version) < 2:
        out.append(f"episodes need format 1.2 or later, info.json says {info.format_version}")
    return out + _storage_problems(info)


def _storage_problems(info: DatasetInfo) -> list[str]:
    """Where sample_storage contradicts the rest: samples as views need format 1.3, the
    episodes they view, and no stored static or slip arrays (no samples_per_shard for them)."""
    storage = info.sample_storage
    if storage is None:
        return []
    if storage not in SAMPLE_STORAGES:
        return [f"sample_storage {storage!r:.60} is not one of {', '.join(SAMPLE_STORAGES)}"]
    out = []
    if format_minor(info.format_version) < format_minor(VIEWS_FORMAT_VERSION):
        out.append(f"sample_storage {storage!r} needs format {VIEWS_FORMAT_VERSION} or later, "
                   f"info.json says {info.format_version}")
    if info.episodes is None:
        out.append(f"sample_storage {storage!r} without episodes (the samples are views of "
                   "them)")
    stored = sorted(k for k in KINDS if k in info.zarr.samples_per_shard)
    if stored:
        out.append(f"zarr.samples_per_shard.{stored[0]} with sample_storage {storage!r} (its "
                   "samples are views of the episode store, nothing of their own is stored)")
    return out


def info_problems(info: DatasetInfo) -> list[str]:
    """Where info.json names what it may not: a split that is no plain name (its file would be
    read from elsewhere), a file outside the dataset, counts of splits it does not list."""
    out = []
    bad = [n for n in info.splits if not SPLIT_NAME.fullmatch(n)]
    if bad:
        out.append(f"splits: {len(bad)} name(s) that are not plain split names (a-z, 0-9 and _, "
                   f"at most 64): {first(bad)}")
    paths = [p for p in info.files
             if p.startswith("/") or any(s in ("", ".", "..") for s in p.split("/"))]
    if paths:
        out.append(f"files: {len(paths)} path(s) outside the dataset folder: {first(paths)}")
    if set(info.counts.splits) != set(info.splits):
        out.append(f"counts.splits names {first(sorted(info.counts.splits))}, splits "
                   f"{first(sorted(info.splits))}")
    return out


def dataset_checksum(files: Mapping[str, str]) -> str:
    """dataset_sha256: sha256 of the lines `path sha256\\n`, sorted by path, of every file under
    data/, index/ and meta/splits/ (UTF-8)."""
    keep = sorted(p for p in files if p.startswith(CHECKSUMMED))
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
    from ...jsonio import loads, read_bytes

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
