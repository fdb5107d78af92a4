"""The rows of the Hugging Face copy (`vtsbench export-hf`): their `datasets` features and
arrow schema, and a view's samples as one arrow table: the index's labels (object, state and
direction as ClassLabel ids), then every frame as an `Image` that `datasets` decodes on access
(so its Arrow cache holds the encoded bytes, not pixels): `rgb` a lossless TIFF (zstd,
horizontal predictor), `depth` a 16-bit TIFF of the stored int16 counts (x the depth scale =
mm), `contact` a 1-bit PNG, and `depth_preview`, a colour-mapped PNG for the Hub viewer, left
encoded by `datasets` (`Image(decode=False)`)."""

from __future__ import annotations

import io
import json
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from ...errors import VtsError
from ...labels import DIRECTION_NAMES, STATES
from ..build.png import depth_preview_pngs
from ..format.records import INDEX_COLUMNS

if TYPE_CHECKING:
    import pyarrow as pa

    from ..read.view import View

#: The layout of the hub rows, in the parquet schema's metadata (`vtsbench` key) and the card.
#: 1: rgb PNG, depth float32 mm as nested lists (9 bytes in the Arrow cache for every byte of
#: the parquet); 2: rgb and depth TIFF (zstd), the preview left encoded.
HUB_VERSION = 2
#: The parquet columns that hold encoded images: written without compression (they are
#: compressed already), so the Arrow cache that `load_dataset` makes holds the same bytes.
IMAGE_COLUMNS = ("rgb", "depth", "contact", "depth_preview")

#: Index columns written as they are (the labels with names are ClassLabel columns).
PLAIN_COLUMNS = ("sample_id", "row", "session", "sensor", "mm_per_px_x", "mm_per_px_y",
                 "press_depth_mm", "contact_x_px", "contact_y_px")
SLIP_PLAIN = ("motion_dx_mm", "motion_dy_mm")


def features_doc(info: Any, kind: str, extra: Sequence[str] = ()) -> dict[str, Any]:
    """The `datasets` features (as the JSON datasets writes) of a kind's hub files; extra: the
    index's own string columns (pattern fields, `take`, meta keys), after `source`."""
    seq = kind == "slip"
    t = info.frames_per_sequence

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
        feats["depth"] = maybe_list({"_type": "Image"})
        feats["contact"] = maybe_list({"_type": "Image"})
        feats["depth_preview"] = maybe_list({"decode": False, "_type": "Image"})
    return feats


def extra_columns(view: View) -> list[str]:
    """The index columns of a view beyond the fixed ones (the recordings' own fields)."""
    return [n for n in view.index.column_names if n not in INDEX_COLUMNS]


def arrow_schema(info: Any, kind: str, extra: Sequence[str] = ()) -> pa.Schema:
    """The arrow schema of a kind's hub files: datasets' own (with the `huggingface` features
    metadata), the layout's version and depth scale under the `vtsbench` key, and the depth's
    encoding on the depth field."""
    import datasets

    schema = datasets.Features.from_dict(features_doc(info, kind, extra)).arrow_schema
    doc: dict[str, Any] = {"hub_version": HUB_VERSION}
    if "depth" in schema.names:
        doc["depth_scale_mm"] = info.depth_scale_mm
        i = schema.get_field_index("depth")
        meta = {"units": "count", "scale_mm": repr(info.depth_scale_mm),
                "meaning": "indentation into the gel, positive into the gel",
                "encoding": "16-bit TIFF of the int16 counts' bits: view as int16, x scale_mm"}
        schema = schema.set(i, schema.field(i).with_metadata(meta))
    return schema.with_metadata({**(schema.metadata or {}),
                                 b"vtsbench": json.dumps(doc).encode()})


def tiff(img: np.ndarray, predictor: bool = True) -> bytes:
    """Lossless TIFF bytes of an RGB uint8 or a grey uint16 frame (the same array gives the same
    bytes): little-endian, one strip of zstd (level 3) with TIFF's horizontal predictor (2) for
    RGB, which any libtiff with zstd reads (Pillow, so `datasets`).

    480x640 RGB, one core: Pillow decodes it in 1.6 ms where a PNG at level 1 takes 2.8 to
    4.7 ms, and it is about as small (0.21 of the raw bytes on simulated frames, PNG 0.18 to
    0.26); the 16-bit depth, without the predictor, decodes in 0.6 ms (PNG 1.3 to 2.4 ms).
    Written here rather than by Pillow, whose libtiff encoder (zstd level 9) took 20 ms a
    frame and holds the GIL: 2.8 ms (level 3, 15 % larger), and export threads share the work.
    """
    import struct

    from numcodecs import Zstd

    a = np.ascontiguousarray(img)
    h, w = a.shape[:2]
    spp, bits = (a.shape[2] if a.ndim == 3 else 1), 8 * a.dtype.itemsize
    a = a.astype(a.dtype.newbyteorder("<"), copy=False)
    if predictor:  # each sample minus the one before it in the row, same channel, wrapping
        d = a.copy()
        d[:, 1:] -= a[:, :-1]
        a = d
    strip = Zstd(level=3).encode(a.tobytes())
    n_tags = 10 + predictor
    bps_at = 8 + 2 + 12 * n_tags + 4  # BitsPerSample values, after the IFD when spp > 1
    data_at = bps_at + (2 * spp if spp > 1 else 0)
    tags = [(256, 4, 1, w), (257, 4, 1, h), (258, 3, spp, bps_at if spp > 1 else bits),
            (259, 3, 1, 50000), (262, 3, 1, 2 if spp == 3 else 1), (273, 4, 1, data_at),
            (277, 3, 1, spp), (278, 4, 1, h), (279, 4, 1, len(strip)), (284, 3, 1, 1)]
    if predictor:
        tags.append((317, 3, 1, 2))
    out = [b"II*\x00", struct.pack("<IH", 8, n_tags)]
    for tag, kind, count, value in tags:  # kind 3 SHORT (one: in the low half), 4 LONG
        one_short = kind == 3 and count == 1
        out.append(struct.pack("<HHIHH", tag, kind, count, value, 0) if one_short
                   else struct.pack("<HHII", tag, kind, count, value))
    out.append(struct.pack("<I", 0))
    if spp > 1:
        out.append(struct.pack(f"<{spp}H", *[bits] * spp))
    out.append(strip)
    return b"".join(out)


def check_codecs() -> None:
    """One line when this Pillow cannot read the TIFFs of the hub copy back (it needs libtiff
    with zstd: the PyPI wheels have it), as `datasets` will."""
    from PIL import Image

    a = np.arange(12, dtype=np.uint8).reshape(2, 2, 3)
    why = ""
    try:
        ok = np.array_equal(np.asarray(Image.open(io.BytesIO(tiff(a)))), a)
    except Exception as e:  # Pillow without libtiff or its zstd codec
        ok, why = False, f" ({type(e).__name__}: {str(e)[:80]})"
    if not ok:
        raise VtsError("export-hf writes zstd TIFFs, and this Pillow cannot read them" + why
                       + "; install Pillow's wheel from PyPI (pip install -U pillow)")


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


def stored_counts(depth_mm: np.ndarray, scale_mm: float) -> np.ndarray:
    """The stored int16 depth counts back from the loader's mm (float32(count) x the scale):
    divided in float64 and rounded, exact for every int16 count and any scale."""
    counts = np.rint(np.asarray(depth_mm, np.float64) / scale_mm)
    return np.clip(counts, -32768, 32767).astype(np.int16)


def _encode_sample(rgb: np.ndarray, depth: np.ndarray | None, contact: np.ndarray | None,
                   scale_mm: float) -> dict[str, list[bytes]]:
    """The images of one sample (one per frame; one for a static sample): rgb and depth
    (int16 counts, as uint16) TIFFs, contact (1-bit PNG) and the depth preview (PNG)."""
    out = {"rgb": [tiff(f) for f in (rgb if rgb.ndim == 4 else rgb[None])]}
    if depth is not None and contact is not None:
        counts = stored_counts(depth if depth.ndim == 3 else depth[None], scale_mm)
        out["depth"] = [tiff(f, predictor=False) for f in counts.view(np.uint16)]
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


def rows_table(view: View, schema: pa.Schema) -> pa.Table:
    """The table of a view's samples: read in one zarr call, images encoded here (libtiff,
    OpenCV and the zarr codecs release the GIL, so batches are made by several threads at
    once)."""
    import pyarrow as pa

    kind = view.kind
    data = view.read(slice(None), view.arrays)
    depth, contact = data.get("depth"), data.get("contact")
    scale = view.dataset.info.depth_scale_mm
    encoded = [_encode_sample(data["rgb"][i], None if depth is None else depth[i],
                              None if contact is None else contact[i], scale)
               for i in range(len(view))]
    cols = _label_columns(view, kind)
    seq = kind == "slip"
    for name in encoded[0]:
        cols[name] = _images([e[name] for e in encoded], seq)
    return pa.Table.from_arrays([_as_type(cols[f.name], f.type) for f in schema], schema=schema)


def _as_type(arr: pa.Array, typ: pa.DataType) -> pa.Array:
    """An array of the field's type: datasets' extension arrays wrap their storage."""
    import pyarrow as pa

    if isinstance(typ, pa.ExtensionType):
        return pa.ExtensionArray.from_storage(typ, arr.cast(typ.storage_type))
    return arr.cast(typ)
