"""The dataset's typed records mirror schemas/{sample,dataset_info,split}.schema.json."""

from __future__ import annotations

import dataclasses
import hashlib
import json

import pyarrow as pa
import pytest

from vtsbench.dataset.format.index import index_schema
from vtsbench.dataset.format.info import (
    FORMAT,
    Calibration,
    Counts,
    DatasetInfo,
    KindCounts,
    ZarrSettings,
    dataset_checksum,
    load_info,
)
from vtsbench.dataset.format.layout import DEPTH_SCALE_MM, KINDS, RGB_ONLY
from vtsbench.dataset.format.records import (
    SLIP_ONLY,
    ArraySpec,
    Sample,
    SampleMeta,
    SplitFile,
    schema,
    schema_errors,
)
from vtsbench.errors import VtsError

SHA = "ab" * 32


def _props(name: str, at: str | None = None) -> set[str]:
    sch = schema(name)
    return set((sch["$defs"][at] if at else sch)["properties"])


def _fields(cls: type) -> set[str]:
    return {f.name for f in dataclasses.fields(cls)}


@pytest.mark.parametrize(("cls", "name", "at"), [
    (SampleMeta, "sample", "index_row"), (Sample, "sample", None),
    (ArraySpec, "sample", "array"), (KindCounts, "dataset_info", "kind_counts"),
    (Counts, "dataset_info", "counts"), (ZarrSettings, "dataset_info", "zarr"),
    (Calibration, "dataset_info", "calibration"), (SplitFile, "split", None),
])
def test_classes_mirror_schema(cls, name, at) -> None:
    assert _fields(cls) == _props(name, at)


def test_info_fields_are_top_level_properties() -> None:
    assert _fields(DatasetInfo) | {"format"} == _props("dataset_info")


def slip_meta(**kw) -> SampleMeta:
    base = dict(sample_id="gear-take3-w002", kind="slip", row=2, object="gear", class_idx=1,
                session="day1", sensor="gs-07", mm_per_px_x=0.0634, mm_per_px_y=0.0634,
                source="day1/gear_3.mov:16-24", press_depth_mm=0.6, contact_x_px=161.0,
                contact_y_px=118.5, state="slip", direction=2, motion_dx_mm=0.02,
                motion_dy_mm=0.41)
    return SampleMeta(**{**base, **kw})


def static_meta(**kw) -> SampleMeta:
    base = dict(sample_id="cube-001", kind="static", row=0, object="cube", class_idx=0,
                session="day1", sensor="gs-07", mm_per_px_x=0.0634, mm_per_px_y=0.0634,
                source="day1/cube_001.png")
    return SampleMeta(**{**base, **kw})


@pytest.mark.parametrize("meta", [slip_meta(), static_meta(), static_meta(press_depth_mm=0.8),
                                  slip_meta(state=None, direction=None, motion_dx_mm=None,
                                            motion_dy_mm=None),
                                  slip_meta(state="press", direction=None)])
def test_sample_meta_validates_and_round_trips(meta) -> None:
    d = meta.to_dict()
    assert schema_errors(d, "sample", "index_row") == []
    assert SampleMeta.from_dict(d) == meta
    assert json.loads(json.dumps(d)) == d


def test_state_idx_is_filled_and_checked() -> None:
    assert slip_meta().state_idx == 2
    assert slip_meta(state="press", direction=None).state_idx == 1
    with pytest.raises(ValueError, match="state_idx"):
        slip_meta(state_idx=0)
    with pytest.raises(ValueError, match="kind"):
        slip_meta(kind="sequence")


@pytest.mark.parametrize(("mutate", "needle"), [
    (lambda d: d.update(kind="static"), "state"),
    (lambda d: d.update(state="press", state_idx=1), "direction"),
    (lambda d: d.update(state_idx=0), "state"),
    (lambda d: d.update(direction=8), "direction"),
    (lambda d: d.update(mm_per_px_x=0.0), "mm_per_px_x"),
    (lambda d: d.update(mm_per_px_x=None), "mm_per_px_y"),  # both known, or neither
    (lambda d: d.update(colour=3), "colour"),  # a recording's own field is a string
    (lambda d: d.update({"Bad Name": "x"}), "Bad Name"),
])
def test_index_row_schema_rejects(mutate, needle) -> None:
    d = slip_meta().to_dict()
    mutate(d)
    errs = schema_errors(d, "sample", "index_row")
    assert errs and any(needle in e for e in errs), errs


@pytest.mark.parametrize("kind", KINDS)
def test_rows_fit_the_index_schema(kind) -> None:
    metas = [slip_meta(), slip_meta(sample_id="b", row=3, state=None, direction=None,
                                    press_depth_mm=None, contact_x_px=None, contact_y_px=None,
                                    motion_dx_mm=None, motion_dy_mm=None)]
    if kind == "static":
        metas = [static_meta(), static_meta(sample_id="c", row=1, contact_x_px=3.0,
                                            contact_y_px=4.0)]
    sch = index_schema(kind)
    assert list(sch.names) == list(metas[0].to_row())
    table = pa.Table.from_pylist([m.to_row() for m in metas], schema=sch)
    assert table.schema == sch
    assert [SampleMeta.from_row(r, kind) for r in table.to_pylist()] == metas
    if kind == "static":
        assert not set(SLIP_ONLY) & set(sch.names)
    assert sch.field("class_idx").type == pa.int32() and sch.field("row").type == pa.int64()
    assert not sch.field("sample_id").nullable and sch.field("press_depth_mm").nullable


def test_index_schema_rejects_unknown_kind() -> None:
    with pytest.raises(ValueError, match="kind"):
        index_schema("press")


@pytest.mark.parametrize(("meta", "frames", "rgb"), [
    (slip_meta(), 8, [8, 240, 320, 3]), (static_meta(contact_x_px=1.0, contact_y_px=2.0), None,
                                         [240, 320, 3]),
])
def test_sample_description_validates_and_round_trips(meta, frames, rgb) -> None:
    s = Sample.from_meta(meta, (240, 320), frames)
    d = s.to_dict()
    assert schema_errors(d, "sample") == []
    assert d["rgb"] == {"dtype": "uint8", "shape": rgb}
    assert d["depth"]["unit"] == "mm" and d["depth"]["depth_scale_mm"] == DEPTH_SCALE_MM
    assert d["depth"]["dtype"] == "int16" and d["contact"]["dtype"] == "bool"
    assert Sample.from_dict(json.loads(json.dumps(d))) == s


def test_sample_description_rules() -> None:
    with pytest.raises(ValueError, match="frames"):
        Sample.from_meta(slip_meta(), (240, 320))
    d = Sample.from_meta(static_meta(), (240, 320)).to_dict()
    assert d["motion_mm"] is None and d["contact_px"] is None and d["state"] is None
    d["rgb"]["shape"] = [8, 240, 320, 3]
    assert any("rgb" in e for e in schema_errors(d, "sample"))
    d = Sample.from_meta(slip_meta(), (240, 320), 8).to_dict()
    del d["depth"]["unit"]
    assert any("unit" in e for e in schema_errors(d, "sample"))


@pytest.mark.parametrize("scale", [None, 0.0634])
def test_rgb_only_sample_description(scale) -> None:
    """A sample of a dataset built with --no-depth: rgb alone; the scale may be unknown."""
    meta = slip_meta(mm_per_px_x=scale, mm_per_px_y=scale)
    assert schema_errors(meta.to_dict(), "sample", "index_row") == []
    s = Sample.from_meta(meta, (240, 320), 8, arrays=RGB_ONLY)
    d = s.to_dict()
    assert "depth" not in d and "contact" not in d
    assert d["mm_per_px"] == (None if scale is None else [scale, scale])
    assert schema_errors(d, "sample") == []
    assert Sample.from_dict(json.loads(json.dumps(d))) == s
    full = Sample.from_meta(meta, (240, 320), 8).to_dict()
    if scale is None:  # depth comes with a scale (the calibration's)
        assert any("mm_per_px" in e for e in schema_errors(full, "sample"))
    else:
        assert schema_errors(full, "sample") == []
    half = {k: v for k, v in full.items() if k != "contact"}  # depth and contact go together
    assert any("contact" in e for e in schema_errors(half, "sample"))
    with pytest.raises(ValueError, match="arrays"):
        Sample.from_meta(meta, (240, 320), 8, arrays=("rgb", "depth"))


def make_info() -> DatasetInfo:
    metas = [slip_meta(), static_meta()]
    split = SplitFile("seen", "slip", "d", 0, {"train": ["gear-take3-w002"]})
    files = {"data/slip.zarr/zarr.json": SHA, "index/slip.parquet": SHA,
             "meta/splits/seen.json": split.sha256(), "README.md": SHA}
    return DatasetInfo(
        name="lab-a", vtsbench_version="0.1.0", frames_per_sequence=8, resolution=(240, 320),
        objects=["cube", "gear"], counts=Counts.of(metas, [split]),
        shapes={"slip": {"rgb": (1, 8, 240, 320, 3), "depth": (1, 8, 240, 320),
                         "contact": (1, 8, 240, 320)},
                "static": {"rgb": (1, 240, 320, 3), "depth": (1, 240, 320),
                           "contact": (1, 240, 320)}},
        zarr=ZarrSettings({"static": 64, "slip": 8}), created_by="test",
        calibration=Calibration("gs-07", "lookup", SHA), splits={"seen": split.sha256()},
        files=files, dataset_sha256=dataset_checksum(files), build={"frames": 8})


def test_info_validates_and_round_trips() -> None:
    info = make_info()
    d = info.to_dict()
    assert schema_errors(d, "dataset_info") == []
    assert d["format"] == FORMAT and d["units"]["depth"] == "mm"
    assert d["depth_scale_mm"] == 0.001 and d["depth_dtype"] == "int16"
    assert DatasetInfo.from_dict(json.loads(info.to_json())) == info
    assert info.class_idx("gear") == 1
    c = d["counts"]
    assert c["slip"]["states"] == {"slip": 1} and c["slip"]["directions"] == {"2": 1}
    assert c["static"]["objects"] == {"cube": 1} and c["static"]["states"] == {}
    assert c["splits"] == {"seen": {"train": 1}}
    d2 = DatasetInfo.from_dict(d)
    d2.calibration = None
    assert schema_errors(d2.to_dict(), "dataset_info") == []


def test_load_info_from_folder_or_file(tmp_path) -> None:
    info = make_info()
    (tmp_path / "meta").mkdir()
    (tmp_path / "meta" / "info.json").write_text(info.to_json())
    assert load_info(tmp_path) == info
    assert load_info(tmp_path / "meta" / "info.json") == info


def _broken(d: dict, what: str) -> dict | str:
    if what == "json":
        return "{not json"
    if what == "major":
        d["format_version"] = "2.0"
    elif what == "format":
        d["format"] = "vtsbench.recordings"
    elif what == "schema":
        d["dataset_version"] = "v1"
    elif what == "unsorted":
        d["objects"] = ["gear", "cube"]
    elif what == "no version":
        del d["format_version"]
    return d


@pytest.mark.parametrize(("what", "needle"), [
    ("json", "invalid JSON"), ("major", "format_version '2.0'"), ("format", "not a vtsbench"),
    ("schema", "dataset_version"), ("unsorted", "not sorted"),
    ("no version", "'format_version' is a required property"),
])
def test_load_info_errors_are_one_line(tmp_path, what, needle) -> None:
    doc = _broken(make_info().to_dict(), what)
    p = tmp_path / "info.json"
    p.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    with pytest.raises(VtsError) as ei:
        load_info(p)
    msg = str(ei.value)
    assert needle in msg and "info.json" in msg and "\n" not in msg, msg


def test_load_info_missing(tmp_path) -> None:
    with pytest.raises(VtsError, match=r"meta/info\.json: not found"):
        load_info(tmp_path)


def test_minor_format_version_is_read(tmp_path) -> None:
    info = make_info()
    info.format_version = "1.3"
    (tmp_path / "info.json").write_text(info.to_json())
    assert load_info(tmp_path / "info.json").format_version == "1.3"


def test_dataset_checksum_covers_data_index_and_splits_only() -> None:
    files = {"index/slip.parquet": SHA, "data/a": "cd" * 32, "meta/splits/x.json": SHA}
    want = hashlib.sha256("".join(f"{p} {files[p]}\n" for p in sorted(files)).encode())
    assert dataset_checksum(files) == want.hexdigest()
    extra = {**files, "README.md": SHA, "meta/info.json": SHA, "preview/slip.parquet": SHA}
    assert dataset_checksum(dict(reversed(extra.items()))) == want.hexdigest()


def test_split_file_round_trip_and_canonical_bytes() -> None:
    sp = SplitFile("unseen_objects", "slip", "d", 3,
                      {"train": ["b", "a"], "test": ["c"]}, ["object:test"], {"k": 1})
    assert sp.parts["train"] == ["a", "b"]
    d = sp.to_dict()
    assert schema_errors(d, "split") == []
    assert SplitFile.from_dict(json.loads(sp.to_json())) == sp
    text = sp.to_json()
    assert text == json.dumps(d, sort_keys=True, indent=1) + "\n" and text.isascii()
    assert sp.sha256() == hashlib.sha256(text.encode()).hexdigest()
    same = SplitFile("unseen_objects", "slip", "d", 3, {"test": ["c"], "train": ["a", "b"]},
                        ["object:test"], {"k": 1})
    assert same.to_bytes() == sp.to_bytes()


@pytest.mark.parametrize(("mutate", "needle"), [
    (lambda d: d.update(kind="press"), "kind"),
    (lambda d: d["parts"].update(holdout=["x"]), "holdout"),
    (lambda d: d.update(disjoint=["colour"]), "disjoint"),
    (lambda d: d["parts"].update(train=["a", "a"]), "parts.train"),
])
def test_split_schema_rejects(mutate, needle) -> None:
    d = SplitFile("seen", "slip", "", 0, {"train": ["a"], "test": ["b"]}, ["session"]).to_dict()
    mutate(d)
    errs = schema_errors(d, "split")
    assert errs and any(needle in e for e in errs), errs


def test_unknown_schema_name() -> None:
    with pytest.raises(ValueError, match="unknown schema"):
        schema("recording")
