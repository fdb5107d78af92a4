"""The Zarr arrays of a dataset: each kind's group layout (shapes, whole samples per shard,
shard file keys), depth stored as int16 counts, and the check of their zarr.json against
info.json (`zarr_problems`, raised by the loader on the first read and listed by verify).

Every array (`rgb`, `depth`, `contact`; `rgb` alone without depth) has one sample per inner
chunk and shards of `samples_per_shard` whole samples, in zarr's sharding layout: chunks
zstd-compressed (level 0: not) and each followed by its crc32c, then the shard index of
(offset, length) pairs (MISSING for an absent chunk) and its crc32c.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .info import DatasetInfo, format_minor
from .layout import ARRAYS, DEPTH_SCALE_MM, STORED_DTYPES
from .problems import SHOWN, short

DEPTH_MIN_MM = -32768 * DEPTH_SCALE_MM
DEPTH_MAX_MM = 32767 * DEPTH_SCALE_MM
#: An absent inner chunk in a shard index (offset and length).
MISSING = 2**64 - 1


def depth_to_int16(depth_mm: np.ndarray, out: np.ndarray | None = None,
                   scratch: bool = False) -> np.ndarray:
    """mm -> int16 counts of DEPTH_SCALE_MM: x 1000 in float32, clipped to the int16 range,
    rounded to nearest (ties to even); NaN -> 0. Into `out` when given; scratch=True lets it
    compute in depth_mm itself (a float32 array the caller no longer needs)."""
    d = np.asarray(depth_mm, np.float32)
    counts = np.multiply(d, np.float32(1 / DEPTH_SCALE_MM), out=d if scratch else None)
    np.clip(counts, -32768, 32767, out=counts)
    np.rint(counts, out=counts)
    nan = np.isnan(counts)
    if nan.any():
        counts[nan] = 0
    if out is None:
        return counts.astype(np.int16)
    out[...] = counts  # the same conversion as astype
    return out


def depth_to_mm(counts: np.ndarray) -> np.ndarray:
    """int16 counts -> mm float32 (counts x DEPTH_SCALE_MM)."""
    return np.asarray(counts).astype(np.float32) * np.float32(DEPTH_SCALE_MM)


@dataclass(frozen=True)
class Layout:
    """Shapes and storage settings of one kind's group (static.zarr or slip.zarr)."""

    kind: str
    n: int
    frame: tuple[int, int]  # (H, W)
    frames: int | None  # T for slip, None for static
    samples_per_shard: int
    level: int  # zstd level; 0 stores the chunks uncompressed
    arrays: tuple[str, ...] = ARRAYS  # RGB_ONLY for a dataset without depth

    def sample_shape(self, name: str) -> tuple[int, ...]:
        lead = (self.frames,) if self.frames else ()
        return (*lead, *self.frame, 3) if name == "rgb" else (*lead, *self.frame)

    def shape(self, name: str) -> tuple[int, ...]:
        return (self.n, *self.sample_shape(name))

    @property
    def n_shards(self) -> int:
        return -(-self.n // self.samples_per_shard)

    def shard_rows(self, k: int) -> range:
        """Rows held by shard k."""
        s = self.samples_per_shard
        return range(k * s, min((k + 1) * s, self.n))

    def shard_key(self, name: str, k: int) -> str:
        """Path of shard k of an array, relative to the group (e.g. `rgb/c/3/0/0/0`)."""
        idx = (k,) + (0,) * len(self.sample_shape(name))
        return f"{name}/c/" + "/".join(map(str, idx))

    def to_dict(self) -> dict[str, Any]:
        return {"n": self.n, "frame": list(self.frame), "frames": self.frames,
                "samples_per_shard": self.samples_per_shard, "level": self.level,
                "arrays": list(self.arrays)}


def _shard_shapes(doc: Mapping[str, Any]) -> tuple[tuple[int, ...], tuple[int, ...]] | None:
    """(inner chunk, shard) shapes of a sharded array's zarr.json, or None if not sharded."""
    try:
        shard = tuple(doc["chunk_grid"]["configuration"]["chunk_shape"])
        codec = doc["codecs"][0]
        if codec["name"] != "sharding_indexed":
            return None
        return tuple(codec["configuration"]["chunk_shape"]), shard
    except (KeyError, IndexError, TypeError):
        return None


def zarr_problems(info: DatasetInfo, kind: str, group: Any,
                  arrays: Mapping[str, Any]) -> list[str]:
    """Problems of one kind's Zarr metadata: `group` is data/<kind>.zarr/zarr.json and
    `arrays` each array's own zarr.json (parsed; None when missing). Every array info.json has
    must be in the consolidated metadata, equal to its own zarr.json, with info.json's shape,
    the format's dtype, one sample per chunk and samples_per_shard per shard; the depth scale
    must be info.json's, and the depth attributes those of the format_version info.json gives
    (1.1 writes the CF scale_factor, 1.0 wrote scale: a 1.0 info.json over arrays written by
    1.1 has been downgraded, which drops its info_sha256)."""
    out = []
    try:
        meta = group["consolidated_metadata"]["metadata"]
        assert isinstance(meta, dict)
    except (KeyError, TypeError, AssertionError):
        return ["zarr.json: no consolidated metadata"]
    sps = info.zarr.samples_per_shard.get(kind, 1)
    for name in info.arrays:
        doc = meta.get(name)
        where = f"{name}"
        if not isinstance(doc, dict):
            out.append(f"{where}: not in the consolidated metadata of zarr.json")
            continue
        own = arrays.get(name)
        if own is None:
            out.append(f"{where}/zarr.json: missing")
        elif own != doc:
            diff = sorted(k for k in set(own) | set(doc) if own.get(k) != doc.get(k))
            out.append(f"{where}/zarr.json contradicts the consolidated metadata in zarr.json "
                       f"({', '.join(map(str, diff[:SHOWN]))})")
        want = tuple(info.shapes.get(kind, {}).get(name, ()))
        shape = doc.get("shape")
        bad = []
        if not isinstance(shape, list) or tuple(shape) != want:
            bad.append(f"shape {short(str(shape), 80)}, info.json says {list(want)}")
        if doc.get("data_type") != STORED_DTYPES[name]:
            bad.append(f"dtype {short(str(doc.get('data_type')), 40)}, expected "
                       f"{STORED_DTYPES[name]}")
        chunks = _shard_shapes(doc)
        if chunks != ((1, *want[1:]), (sps, *want[1:])):
            bad.append(f"chunks / shards {short(str(chunks), 80)}, expected one sample per "
                       f"chunk and {sps} per shard")
        attrs = doc.get("attributes") if isinstance(doc.get("attributes"), dict) else {}
        if name == "depth":
            bad += _depth_attr_problems(info, attrs)
        out += [f"{where}: {b}" for b in bad]
    return out


def _depth_attr_problems(info: DatasetInfo, attrs: Mapping[str, Any]) -> list[str]:
    new = format_minor(info.format_version) >= 1
    key = "scale_factor" if new else "scale"
    stray = "scale" if new else "scale_factor"
    if stray in attrs and key not in attrs:
        return [f"attribute {stray!r} is written by format "
                f"{'1.0' if new else '1.1 and later'}, info.json says format_version "
                f"{info.format_version} (an info.json replaced or downgraded after the build)"]
    scale = attrs.get(key)
    if scale != info.depth_scale_mm:
        return [f"depth scale {short(str(scale), 40)} mm ({key}) contradicts info.json "
                f"depth_scale_mm {info.depth_scale_mm}"]
    return []
