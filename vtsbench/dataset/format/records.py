"""The typed records of a dataset's rows and files: index rows (SampleMeta), loaded samples
(Sample, ArraySpec) and split files (SplitFile), and the JSON Schemas they mirror.

Every class mirrors a JSON Schema in `schemas/` (sample, split; info.json's in format/info.py),
and a test keeps the two in step.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

from ...labels import STATES
from .layout import ARRAYS, DEPTH_DTYPE, DEPTH_SCALE_MM, KINDS, RGB_ONLY, STORED_DTYPES

SCHEMA_DIR = Path(__file__).resolve().parent.parent.parent / "schemas"
SCHEMA_NAMES = ("sample", "dataset_info", "split")
#: Index columns in table order; the static index omits SLIP_ONLY.
INDEX_COLUMNS = ("sample_id", "row", "object", "class_idx", "session", "sensor", "mm_per_px_x",
                 "mm_per_px_y", "press_depth_mm", "contact_x_px", "contact_y_px", "state",
                 "state_idx", "direction", "motion_dx_mm", "motion_dy_mm", "source")
SLIP_ONLY = ("state", "state_idx", "direction", "motion_dx_mm", "motion_dy_mm")
#: A split name: the split schema's `name` (it is also the file name under meta/splits/).
SPLIT_NAME = re.compile(r"[a-z0-9][a-z0-9_]{0,63}")
#: The parts of a split scheme before its folds (fold0, fold1, ...).
PART_ORDER = ("train", "val", "test")


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

    from ...jsonio import strict_validator

    validator = strict_validator(sch)
    out = []
    for err in sorted(validator.iter_errors(doc), key=lambda e: list(map(str, e.absolute_path))):
        where = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in err.absolute_path)
        best = jsonschema.exceptions.best_match([err]) if err.context else err
        out.append(f"{where.lstrip('.') or '(top level)'}: {best.message}")
    return out


def _pair(v: Any) -> tuple[float, float] | None:
    return None if v is None else (float(v[0]), float(v[1]))


def part_key(part: str) -> tuple[int, int, str]:
    """Sort key of a split's part names: train, val, test, then folds by number."""
    if part in PART_ORDER:
        return (0, PART_ORDER.index(part), part)
    digits = part[4:] if part.startswith("fold") else ""
    if digits.isascii() and digits.isdigit() and len(digits) < 18:
        return (1, int(digits), part)
    return (2, 0, part)


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
        cols = INDEX_COLUMNS if self.kind == "slip" else static_columns()
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


def static_columns() -> tuple[str, ...]:
    """The static index's columns: INDEX_COLUMNS without the slip-only ones."""
    return tuple(c for c in INDEX_COLUMNS if c not in SLIP_ONLY)


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
                   None if None in scale else _pair(scale),
                   ArraySpec(STORED_DTYPES["rgb"], (*hw, 3)),
                   ArraySpec(depth_dtype, hw, "mm", depth_scale_mm) if depth else None,
                   ArraySpec(STORED_DTYPES["contact"], hw) if depth else None,
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
        for k in ARRAYS:
            args[k] = None if d.get(k) is None and k != "rgb" else ArraySpec.from_dict(d[k])
        for k in ("mm_per_px", "contact_px", "motion_mm"):
            args[k] = _pair(args[k])
        return cls(**args)


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
