"""Zarr v3 arrays of a dataset: layout, metadata, whole-shard encoding, reading from a path or URL.

Every array (`rgb`, `depth`, `contact`; `rgb` alone without depth) has one sample per inner
chunk and shards of `samples_per_shard` whole samples. Shards are encoded in memory, in zarr's
sharding layout with the codecs the metadata declares (the bytes zarr itself writes for an array
of the shard's rows), and written as one file through a temporary name and a rename, so a shard
file is complete or absent and a build can write shards from many processes without zarr ever
reading back a partial shard. Inner chunks are zstd-compressed (level 0: not compressed) and
carry a crc32c, so a damaged byte is pinned to one sample on reading.
"""

from __future__ import annotations

import json
import os
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..atomic import write_bytes_atomic
from ..errors import VtsError

ARRAYS = ("rgb", "depth", "contact")
#: The arrays of a dataset built without depth (`vtsbench build --no-depth`).
RGB_ONLY = ("rgb",)
KINDS = ("static", "slip")
DTYPES = {"rgb": "uint8", "depth": "int16", "contact": "bool"}
#: Depth is stored as int16 counts of this many mm: +-32.767 mm in 1 um steps.
DEPTH_SCALE_MM = 0.001
DEPTH_MIN_MM = -32768 * DEPTH_SCALE_MM
DEPTH_MAX_MM = 32767 * DEPTH_SCALE_MM
#: Target uncompressed size of one RGB shard; depth and contact shards hold the same samples.
SHARD_BYTES = 32 * 2**20


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


def samples_per_shard(frame: tuple[int, int], frames: int | None,
                      target_bytes: int = SHARD_BYTES) -> int:
    """Whole samples per shard so that an RGB shard is about target_bytes uncompressed."""
    rgb = frame[0] * frame[1] * 3 * (frames or 1)
    return max(1, int(target_bytes) // rgb)


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


def _codecs(level: int) -> list[Any]:
    from zarr.codecs import Crc32cCodec, ZstdCodec

    return ([ZstdCodec(level=level), Crc32cCodec()] if level > 0 else [Crc32cCodec()])


def _create(store: Any, layout: Layout, n: int,
            names: tuple[str, ...] | None = None) -> dict[str, Any]:
    """Create the group and its arrays (default: the layout's) with n rows on a zarr store;
    returns the arrays."""
    import zarr

    group = zarr.create_group(store, attributes=_group_attrs(layout), overwrite=True)
    out = {}
    for name in layout.arrays if names is None else names:
        sample = layout.sample_shape(name)
        out[name] = group.create_array(
            name, shape=(n, *sample), dtype=DTYPES[name], chunks=(1, *sample),
            shards=(layout.samples_per_shard, *sample), compressors=_codecs(layout.level),
            fill_value=0 if name != "contact" else False, attributes=_array_attrs(name),
            dimension_names=_dims(name, layout.frames is not None),
            config={"write_empty_chunks": True})
    return out


def _dims(name: str, seq: bool) -> list[str]:
    dims = ["sample", *(["frame"] if seq else []), "y", "x"]
    return [*dims, "channel"] if name == "rgb" else dims


def _group_attrs(layout: Layout) -> dict[str, Any]:
    return {"vtsbench": {"kind": layout.kind, "samples_per_shard": layout.samples_per_shard,
                         "frames": layout.frames, "compression": _compression(layout.level)}}


def _compression(level: int) -> str:
    return f"zstd level {level}" if level > 0 else "none"


def _array_attrs(name: str) -> dict[str, Any]:
    if name == "depth":
        # CF conventions (scale_factor, add_offset, units), so that xarray and other CF
        # readers give millimetres; no _FillValue: 0 is a valid depth (no indentation), and
        # every chunk is written, so there is nothing to mask
        return {"units": "mm", "scale_factor": DEPTH_SCALE_MM,
                "long_name": "indentation depth into the gel",
                "meaning": "indentation into the gel, positive into the gel",
                "clipped_to_mm": [DEPTH_MIN_MM, DEPTH_MAX_MM]}
    if name == "rgb":
        return {"channels": "RGB"}
    return {"meaning": "contact mask estimated with the depth"}


def write_metadata(group_dir: Path, layout: Layout) -> list[Path]:
    """Write the group's and arrays' zarr.json (consolidated) without touching any shard file."""
    import zarr
    from zarr.storage import MemoryStore

    docs: dict[str, Any] = {}
    store = MemoryStore(docs)
    _create(store, layout, layout.n)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # consolidated metadata is not in the v3 spec yet
        zarr.consolidate_metadata(store)
    written = []
    for key, buf in sorted(docs.items()):
        if key.endswith("zarr.json"):
            path = group_dir / key
            path.parent.mkdir(parents=True, exist_ok=True)
            write_bytes_atomic(path, buf.to_bytes())
            written.append(path)
    return written


def encode_shard(layout: Layout, name: str, block: np.ndarray) -> bytes:
    """The bytes of one shard file holding `block` (the shard's rows, in order).

    The codecs the arrays' metadata declares, applied here in zarr's sharding layout: each
    chunk (one sample, C order, little-endian) through numcodecs' zstd (what zarr's ZstdCodec
    calls) and followed by its crc32c, in row order, then the index of (offset, length) pairs,
    absent chunks 2^64 - 1, and its crc32c. The same bytes as zarr's own encoding
    (`encode_shard_zarr`; tests/test_store.py compares them), in 2.3 ms a 480x640 frame for
    rgb, depth and contact against 3.2 ms through zarr's codec pipeline, and without zarr in
    the build's workers.
    """
    _check_block(layout, name, block)
    return b"".join(_direct_shard(layout, name, block))


def encode_shard_zarr(layout: Layout, name: str, block: np.ndarray) -> bytes:
    """The bytes of one shard file holding `block`, encoded by zarr itself (the reference)."""
    from zarr.storage import MemoryStore

    _check_block(layout, name, block)
    docs: dict[str, Any] = {}
    arr = _create(MemoryStore(docs), layout, len(block), (name,))[name]
    arr[...] = block.astype(DTYPES[name], copy=False)
    return docs[layout.shard_key(name, 0)].to_bytes()


def _check_block(layout: Layout, name: str, block: np.ndarray) -> None:
    want = (len(block), *layout.sample_shape(name))
    if block.shape != want or len(block) > layout.samples_per_shard or not len(block):
        raise ValueError(f"{name}: shard block of shape {block.shape}, expected {want} with at "
                         f"most {layout.samples_per_shard} rows")


#: An absent inner chunk in a shard index (offset and length).
_MISSING = 2**64 - 1


def _direct_shard(layout: Layout, name: str, block: np.ndarray) -> list[bytes]:
    """The parts of a shard file, in order (joined, they are its bytes)."""
    import google_crc32c
    from numcodecs import Zstd

    zstd = Zstd(level=layout.level) if layout.level > 0 else None
    index = np.full((layout.samples_per_shard, 2), _MISSING, "<u8")
    parts: list[bytes] = []
    offset = 0
    for i in range(len(block)):
        raw = np.ascontiguousarray(block[i], DTYPES[name])
        data = zstd.encode(raw) if zstd is not None else raw.tobytes()
        parts += [data, google_crc32c.value(data).to_bytes(4, "little")]
        index[i] = (offset, len(data) + 4)
        offset += len(data) + 4
    raw_index = index.tobytes()
    parts += [raw_index, google_crc32c.value(raw_index).to_bytes(4, "little")]
    return parts


def write_shard(group_dir: Path, layout: Layout, k: int, blocks: dict[str, np.ndarray],
                digests: dict[str, str] | None = None) -> dict[str, int]:
    """Encode and write shard k of every array of the layout; returns each file's size in bytes,
    and puts the sha256 of each file's bytes into `digests` when given (no need to read them
    back)."""
    import hashlib

    sizes = {}
    for name in layout.arrays:
        _check_block(layout, name, blocks[name])
        # written and hashed part by part: joining them first copied the shard once more
        # (about 0.8 MB a 480x640 frame)
        parts = _direct_shard(layout, name, blocks[name])
        path = group_dir / layout.shard_key(name, k)
        path.parent.mkdir(parents=True, exist_ok=True)
        write_bytes_atomic(path, parts)
        sizes[name] = sum(map(len, parts))
        if digests is not None:
            h = hashlib.sha256()
            for part in parts:
                h.update(part)
            digests[name] = h.hexdigest()
    return sizes


def write_json(path: Path, doc: Any) -> None:
    """Write JSON with sorted keys and a final newline (stable bytes)."""
    write_bytes_atomic(path, (json.dumps(doc, indent=1, sort_keys=True, allow_nan=False) + "\n")
               .encode("utf-8"))


def _is_url(location: str | os.PathLike) -> bool:
    return "://" in str(location)


def group_location(root: str | os.PathLike, kind: str) -> str:
    """Location of a kind's group under a dataset root (path or URL)."""
    return f"{str(root).rstrip('/')}/data/{kind}.zarr"


def open_group(root: str | os.PathLike, kind: str,
               storage_options: dict[str, Any] | None = None) -> Any:
    """Open a dataset's `static` or `slip` group read-only, from a path or an fsspec URL (read
    through dataset.location: timeouts, size limits, servers without byte ranges)."""
    import zarr
    from zarr.storage import LocalStore

    from ..jsonio import loads, read_json

    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    loc = group_location(root, kind)
    if _is_url(loc):
        from .location import read_remote, remote_store

        meta = f"{loc}/zarr.json"  # within the metadata size limit; NaN, deep nesting...
        loads(read_remote(meta, storage_options, missing="no such Zarr group"), meta,
              "Zarr metadata")
        store = remote_store(loc, storage_options)
    else:
        if not Path(loc).is_dir():
            raise VtsError("no such Zarr group", loc)
        store = LocalStore(loc, read_only=True)
        read_json(Path(loc) / "zarr.json", "Zarr metadata")  # NaN, deep nesting, a device...
    try:
        return zarr.open_group(store, mode="r", use_consolidated=True)
    except VtsError:
        raise
    except Exception as e:  # a changed zarr.json: zarr raises TypeError, ValueError, KeyError...
        text = str(e).strip().splitlines()[0][:120] if str(e).strip() else ""
        raise VtsError(f"cannot open the Zarr group ({type(e).__name__}: {text}; its zarr.json "
                       "was changed?)", loc) from None
