"""The recordings manifest (`recordings.json`): typed classes mirroring its JSON Schema.

A recordings folder holds one manifest that refers to image files, image folders and video
files in place by relative path. `load_manifest` validates against the JSON Schema first, so
every consumer sees a well-formed manifest, and raises a one-line `VtsError` otherwise.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

from ..errors import VtsError

MANIFEST_NAME = "recordings.json"
FORMAT = "vtsbench.recordings"
FORMAT_VERSION = "1.0"
KINDS = ("static", "sequence", "press")
SCHEMA_PATH = Path(__file__).resolve().parent.parent / "schemas" / "recording.schema.json"


@lru_cache(maxsize=1)
def schema() -> dict[str, Any]:
    """The recordings JSON Schema shipped with the package."""
    return json.loads(SCHEMA_PATH.read_text())


@dataclass(frozen=True)
class Mount:
    """How the sensor is mounted: stage/robot (x, y) -> image (x right, y up)."""

    rotation_deg: float = 0.0
    mirror: bool = False
    description: str = ""

    def to_image(self, dx: float, dy: float) -> tuple[float, float]:
        """Map a stage displacement to the image frame: mirror x if set, then rotate CCW."""
        if self.mirror:
            dx = -dx
        c, s = math.cos(math.radians(self.rotation_deg)), math.sin(math.radians(self.rotation_deg))
        return (c * dx - s * dy, s * dx + c * dy)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"rotation_deg": self.rotation_deg, "mirror": self.mirror}
        if self.description:
            d["description"] = self.description
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Mount:
        return cls(float(d.get("rotation_deg", 0.0)), bool(d.get("mirror", False)),
                   d.get("description", ""))


@dataclass(frozen=True)
class Session:
    """One sitting of one sensor: resolution, scale, frame rate, background and mounting."""

    id: str
    sensor: str
    resolution: tuple[int, int]  # (height, width)
    mm_per_px: tuple[float, float] | None = None  # (x, y)
    fps: float | None = None
    background: str | None = None
    background_frame: int | None = None
    mount: Mount = field(default_factory=Mount)
    notes: str = ""

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"id": self.id, "sensor": self.sensor,
                             "resolution": list(self.resolution)}
        if self.mm_per_px is None:
            d["mm_per_px"] = None
        else:
            mx, my = self.mm_per_px
            d["mm_per_px"] = mx if mx == my else [mx, my]
        d["fps"] = self.fps
        d["background"] = self.background
        if self.background_frame is not None:
            d["background_frame"] = self.background_frame
        d["mount"] = self.mount.to_dict()
        if self.notes:
            d["notes"] = self.notes
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Session:
        mm = d.get("mm_per_px")
        if mm is not None:
            mm = (float(mm), float(mm)) if isinstance(mm, (int, float)) else (float(mm[0]),
                                                                               float(mm[1]))
        return cls(id=d["id"], sensor=d["sensor"],
                   resolution=(int(d["resolution"][0]), int(d["resolution"][1])),
                   mm_per_px=mm, fps=d.get("fps"), background=d.get("background"),
                   background_frame=d.get("background_frame"),
                   mount=Mount.from_dict(d.get("mount", {})), notes=d.get("notes", ""))


@dataclass(frozen=True)
class Source:
    """Where an entry's frames are: a file, a video or an image folder, plus a frame or range."""

    path: str
    frame: int | None = None
    start: int | None = None
    stop: int | None = None

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"path": self.path}
        for k in ("frame", "start", "stop"):
            v = getattr(self, k)
            if v is not None:
                d[k] = v
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Source:
        return cls(d["path"], d.get("frame"), d.get("start"), d.get("stop"))


@dataclass(frozen=True)
class Circle:
    """A contact circle in pixels (y down the rows)."""

    x: float
    y: float
    r: float

    def to_dict(self) -> dict[str, float]:
        return {"x": self.x, "y": self.y, "r": self.r}


@dataclass(frozen=True)
class Labels:
    """What is known about an entry; None means unknown."""

    state: str | None = None
    direction: int | None = None
    motion_mm: tuple[float, float] | None = None
    press_depth_mm: float | None = None
    contact_px: tuple[float, float] | None = None

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {}
        for k in ("state", "direction", "motion_mm", "press_depth_mm", "contact_px"):
            v = getattr(self, k)
            if v is not None:
                d[k] = list(v) if isinstance(v, tuple) else v
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Labels:
        def pair(v: Any) -> tuple[float, float] | None:
            return None if v is None else (float(v[0]), float(v[1]))

        return cls(d.get("state"), d.get("direction"), pair(d.get("motion_mm")),
                   d.get("press_depth_mm"), pair(d.get("contact_px")))


@dataclass(frozen=True)
class Entry:
    """A static frame, a sequence, or a calibration press."""

    id: str
    kind: str
    session: str
    source: Source
    object: str | None = None
    take: str | None = None
    labels: Labels = field(default_factory=Labels)
    ball_radius_mm: float | None = None
    circle: Circle | None = None
    truth: str | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"id": self.id, "kind": self.kind, "session": self.session,
                             "source": self.source.to_dict()}
        if self.object is not None:
            d["object"] = self.object
        if self.take is not None:
            d["take"] = self.take
        d["labels"] = self.labels.to_dict()
        if self.kind == "press" or self.ball_radius_mm is not None:
            d["ball_radius_mm"] = self.ball_radius_mm
        if self.circle is not None:
            d["circle"] = self.circle.to_dict()
        if self.truth is not None:
            d["truth"] = self.truth
        if self.meta:
            d["meta"] = self.meta
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Entry:
        c = d.get("circle")
        return cls(id=d["id"], kind=d["kind"], session=d["session"],
                   source=Source.from_dict(d["source"]), object=d.get("object"),
                   take=d.get("take"), labels=Labels.from_dict(d.get("labels", {})),
                   ball_radius_mm=d.get("ball_radius_mm"),
                   circle=None if c is None else Circle(float(c["x"]), float(c["y"]),
                                                        float(c["r"])),
                   truth=d.get("truth"), meta=dict(d.get("meta", {})))


@dataclass
class Manifest:
    """A recordings folder's manifest: sessions and entries."""

    sessions: list[Session]
    entries: list[Entry]
    name: str = ""
    description: str = ""
    created_by: str = ""
    format_version: str = FORMAT_VERSION

    def session(self, session_id: str) -> Session:
        for s in self.sessions:
            if s.id == session_id:
                return s
        raise KeyError(session_id)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"format": FORMAT, "format_version": self.format_version}
        for k in ("name", "description", "created_by"):
            if getattr(self, k):
                d[k] = getattr(self, k)
        d["sessions"] = [s.to_dict() for s in self.sessions]
        d["entries"] = [e.to_dict() for e in self.entries]
        return d

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=1, sort_keys=False, allow_nan=False) + "\n"

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Manifest:
        return cls(sessions=[Session.from_dict(s) for s in d["sessions"]],
                   entries=[Entry.from_dict(e) for e in d["entries"]], name=d.get("name", ""),
                   description=d.get("description", ""), created_by=d.get("created_by", ""),
                   format_version=d["format_version"])


#: schema_errors of the last documents validated, by the sha256 of their canonical JSON: a build
#: loads the manifest and then checks the folder, which validates the same document again
#: (jsonschema takes about 1 ms an entry: 0.27 s for the build benchmark's 262 entries).
_VALIDATED: dict[str, list[str]] = {}


def schema_errors(doc: Any) -> list[str]:
    """Every schema violation of a manifest document, one readable line each."""
    import hashlib
    import json

    try:
        key = hashlib.sha256(json.dumps(doc, sort_keys=True, allow_nan=False).encode()).hexdigest()
    except (TypeError, ValueError):  # not plain JSON: validate without remembering
        return _schema_errors(doc)
    if key not in _VALIDATED:
        if len(_VALIDATED) >= 4:
            _VALIDATED.pop(next(iter(_VALIDATED)))
        _VALIDATED[key] = _schema_errors(doc)
    return list(_VALIDATED[key])


def _schema_errors(doc: Any) -> list[str]:
    import jsonschema

    from ..jsonio import strict_validator

    validator = strict_validator(schema())
    out = []
    for err in sorted(validator.iter_errors(doc), key=lambda e: list(map(str, e.absolute_path))):
        where = _json_path(doc, list(err.absolute_path))
        # oneOf failures are hard to read; report the most specific sub-error instead.
        best = jsonschema.exceptions.best_match([err]) if err.context else err
        out.append(f"{where}: {best.message}")
    return out


def _json_path(doc: Any, parts: list[Any]) -> str:
    """A readable location such as `entries[3] (seq-0004).labels.direction`."""
    text, node = "", doc
    for p in parts:
        if isinstance(p, int):
            text += f"[{p}]"
            node = node[p] if isinstance(node, list) and p < len(node) else None
            if isinstance(node, dict) and isinstance(node.get("id"), str):
                text += f" ({node['id']})"
        else:
            text += f".{p}" if text else str(p)
            node = node.get(p) if isinstance(node, dict) else None
    return text or "(top level)"


def read_manifest_doc(folder: str | Path) -> tuple[Path, Any]:
    """Read the raw JSON of a folder's manifest, raising a one-line error if absent or invalid."""
    folder = Path(folder)
    if not folder.is_dir():
        hint = (f"; a data pack of ball presses becomes one with `vtsbench import-presses "
                f"{folder} --out REC`" if folder.suffix.lower() == ".npz" else "")
        raise VtsError(f"not a folder (expected a recordings folder){hint}", folder)
    path = folder / MANIFEST_NAME
    if not path.is_file():
        how = ("it looks like a gs_sdk calibration folder: `vtsbench import-presses "
               f"{folder} --out REC` describes it" if (folder / "catalog.csv").is_file()
               else "write one with `vtsbench manifest` or `vtsbench collect`")
        raise VtsError(f"no {MANIFEST_NAME} ({how})", folder)
    from ..jsonio import read_json

    return path, read_json(path)


def load_manifest(folder: str | Path) -> Manifest:
    """Load and schema-validate a recordings folder's manifest."""
    path, doc = read_manifest_doc(folder)
    errs = schema_errors(doc)
    if errs:
        more = f" (and {len(errs) - 1} more; run `vtsbench check`)" if len(errs) > 1 else ""
        raise VtsError(f"{errs[0]}{more}", path)
    return Manifest.from_dict(doc)


def save_manifest(folder: str | Path, manifest: Manifest) -> Path:
    """Validate and write a manifest atomically; returns its path."""
    from ..atomic import write_text_atomic

    doc = manifest.to_dict()
    errs = schema_errors(doc)
    path = Path(folder) / MANIFEST_NAME
    if errs:  # options that make an invalid manifest (a negative radius, a session '../x'...)
        raise VtsError(f"refusing to write an invalid manifest: {errs[0]}", path)
    write_text_atomic(path, manifest.to_json())
    return path
