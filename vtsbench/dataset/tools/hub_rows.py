"""The rows of the Hugging Face copy (`vtsbench export-hf`): their `datasets` features and
arrow schema, and a view's samples as one arrow table: the index's labels (object, state and
direction as ClassLabel ids), `rgb` and `contact` as PNG images, `depth` as float32 mm (the
loader's values) and `depth_preview`, a colour-mapped PNG for the Hub viewer."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from ...labels import DIRECTION_NAMES, STATES
from ..build.png import depth_preview_pngs, png
from ..format.layout import DECODED_DTYPES
from ..format.records import INDEX_COLUMNS

if TYPE_CHECKING:
    import pyarrow as pa

    from ..read.view import View

#: Index columns written as they are (the labels with names are ClassLabel columns).
PLAIN_COLUMNS = ("sample_id", "row", "session", "sensor", "mm_per_px_x", "mm_per_px_y",
                 "press_depth_mm", "contact_x_px", "contact_y_px")
SLIP_PLAIN = ("motion_dx_mm", "motion_dy_mm")


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
        feats["depth"] = {"shape": shape, "dtype": DECODED_DTYPES["depth"], "_type": array}
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


def rows_table(view: View, schema: pa.Schema) -> pa.Table:
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
