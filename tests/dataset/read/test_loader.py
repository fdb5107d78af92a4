"""vtsbench.load: views, samples, batch reads, filters, splits, partial reads and errors."""

from __future__ import annotations

import io
import json
import pickle
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import vtsbench
from vtsbench.dataset.format.records import schema_errors
from vtsbench.dataset.read import loader
from vtsbench.dataset.read.view import SampleIndexError, View
from vtsbench.errors import VtsError


@pytest.fixture(scope="module")
def ds(vts_dataset: Path) -> loader.VtsDataset:
    return vtsbench.load(vts_dataset)


def one_line(e: pytest.ExceptionInfo[BaseException]) -> str:
    text = str(e.value)
    assert "\n" not in text
    return text


def test_load_reads_info_and_indexes(ds: loader.VtsDataset, vts_dataset: Path) -> None:
    info = json.loads((vts_dataset / "meta" / "info.json").read_text())
    assert ds.info.name == info["name"]
    assert len(ds.static) == info["counts"]["static"]["samples"] == info["shapes"]["static"][
        "rgb"][0]
    assert len(ds.slip) == info["counts"]["slip"]["samples"] > 0
    assert ds.splits == sorted(info["splits"])
    assert ds.location == str(vts_dataset)
    assert "slip" in repr(ds.slip) and str(len(ds.slip)) in repr(ds)


@pytest.mark.parametrize("kind", ["static", "slip"])
def test_sample_matches_zarr_and_schema(ds: loader.VtsDataset, vts_dataset: Path,
                                        kind: str, zarr_rows) -> None:
    view = ds.view(kind)
    i = len(view) - 1
    s = view[i]
    row = int(view.index.column("row")[i].as_py())
    assert s["rgb"].dtype == np.uint8 and s["depth"].dtype == np.float32
    assert s["contact"].dtype == bool
    np.testing.assert_array_equal(s["rgb"], zarr_rows(vts_dataset, kind, "rgb", [row])[0])
    np.testing.assert_array_equal(s["contact"], zarr_rows(vts_dataset, kind, "contact", [row])[0])
    counts = zarr_rows(vts_dataset, kind, "depth", [row])[0]
    np.testing.assert_allclose(s["depth"], counts.astype(np.float64) * ds.info.depth_scale_mm,
                               rtol=1e-6)
    assert s["rgb"].shape == tuple(ds.info.shapes[kind]["rgb"][1:])
    assert s["sample_id"] == view.ids[i] and s["kind"] == kind
    assert s["class_idx"] == ds.info.objects.index(s["object"])
    described = {k: v for k, v in s.items() if k not in ("rgb", "depth", "contact")}
    for name in ("rgb", "depth", "contact"):
        described[name] = {"dtype": str(s[name].dtype), "shape": list(s[name].shape)}
    described["depth"].update(unit="mm", depth_scale_mm=1.0)
    assert schema_errors(json.loads(json.dumps(described)), "sample") == []
    assert view[-1]["sample_id"] == s["sample_id"]


def test_slip_sample_labels(ds: loader.VtsDataset) -> None:
    idx = ds.slip.index.to_pylist()
    for k, s in enumerate(ds.slip.metas(range(len(ds.slip)))):
        r = idx[k]
        assert s["state"] == r["state"] and s["state_idx"] == r["state_idx"]
        assert s["direction"] == r["direction"]
        want = None if r["motion_dx_mm"] is None else (r["motion_dx_mm"], r["motion_dy_mm"])
        assert s["motion_mm"] == want
        assert s["mm_per_px"] == (r["mm_per_px_x"], r["mm_per_px_y"])
    static = ds.static.metas(range(len(ds.static)))
    assert all(s["state"] is None and s["motion_mm"] is None for s in static)


def test_read_keeps_the_order_asked(ds: loader.VtsDataset, vts_dataset: Path,
                                    zarr_rows) -> None:
    view = ds.slip
    n = len(view)
    items = [n - 1, 0, 1, n - 1, n // 2]
    got = view.read(items, ("rgb", "depth", "contact"))
    rows = view.rows[items]
    np.testing.assert_array_equal(got["rgb"], zarr_rows(vts_dataset, "slip", "rgb", rows))
    np.testing.assert_array_equal(got["contact"],
                                  zarr_rows(vts_dataset, "slip", "contact", rows))
    assert got["depth"].dtype == np.float32 and got["depth"].shape[0] == len(items)
    sl = view.read(slice(1, 3))
    np.testing.assert_array_equal(sl["rgb"], zarr_rows(vts_dataset, "slip", "rgb",
                                                       view.rows[1:3]))
    assert view.read([], ("rgb", "depth"))["depth"].shape == (0, *ds.info.shapes["slip"][
        "depth"][1:])


def test_read_frames(ds: loader.VtsDataset) -> None:
    t = ds.info.frames_per_sequence
    full = ds.slip.read([0, 1], ("rgb", "depth"))
    part = ds.slip.read([0, 1], ("rgb", "depth"), frames=[0, t - 1])
    np.testing.assert_array_equal(part["rgb"], full["rgb"][:, [0, t - 1]])
    np.testing.assert_array_equal(part["depth"], full["depth"][:, [0, t - 1]])
    with pytest.raises(VtsError, match="frame numbers"):
        ds.slip.read([0], frames=[t])
    with pytest.raises(VtsError, match="slip sequences only"):
        ds.static.read([0], frames=[0])


def test_one_zarr_call_per_contiguous_run(ds: loader.VtsDataset,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[tuple[int, int]] = []
    real = loader._read_runs

    def counting(arr, runs, n, frames):  # type: ignore[no-untyped-def]
        calls.extend(runs)
        return real(arr, runs, n, frames)

    monkeypatch.setattr(loader, "_read_runs", counting)
    view = ds.slip
    n = len(view)
    if n < 4:
        pytest.skip("needs 4 slip samples")
    items = [n - 1, 0, 1, 2, n - 1]  # rows 0-2 (one run) and n-1 (another), asked out of order
    view.read(items, ("rgb",))
    want = {(int(view.rows[0]), int(view.rows[2]) + 1), (int(view.rows[n - 1]),
                                                           int(view.rows[n - 1]) + 1)}
    assert set(calls) == want and len(calls) == 2


def test_iteration_matches_indexing(ds: loader.VtsDataset) -> None:
    view = ds.static
    samples = list(view)
    assert [s["sample_id"] for s in samples] == view.ids
    k = len(view) // 2
    np.testing.assert_array_equal(samples[k]["depth"], view[k]["depth"])


def test_sub_views_and_index(ds: loader.VtsDataset) -> None:
    view = ds.slip
    sub = view[1:3]
    assert isinstance(sub, View) and sub.ids == view.ids[1:3]
    assert sub.index.column("sample_id").to_pylist() == view.ids[1:3]
    assert sub[0]["sample_id"] == view.ids[1]


def test_by_id(ds: loader.VtsDataset) -> None:
    sid = ds.slip.ids[-1]
    assert ds.slip.by_id(sid)["sample_id"] == sid
    assert ds.by_id(ds.static.ids[0])["kind"] == "static"
    assert set(ds.slip.by_id(sid, arrays=("rgb",))) & {"depth", "contact"} == set()
    with pytest.raises(VtsError, match="unknown sample id 'nope'") as e:
        ds.slip.by_id("nope")
    one_line(e)
    with pytest.raises(VtsError, match="not in this view"):
        ds.slip[1:].by_id(ds.slip.ids[0])
    with pytest.raises(VtsError, match="unknown sample id"):
        ds.by_id("nope")


def test_index_out_of_range(ds: loader.VtsDataset) -> None:
    n = len(ds.static)
    for i in (n, -n - 1):
        with pytest.raises(SampleIndexError, match="out of range") as e:
            ds.static[i]
        assert isinstance(e.value, IndexError) and isinstance(e.value, VtsError)
        one_line(e)
    with pytest.raises(SampleIndexError):
        ds.static.read([0, n])


def test_where_filters_through_the_index(ds: loader.VtsDataset) -> None:
    idx = ds.slip.index.to_pylist()
    obj = idx[0]["object"]
    sess = idx[0]["session"]
    got = ds.slip.where(object=obj)
    assert got.ids == [r["sample_id"] for r in idx if r["object"] == obj]
    both = ds.slip.where(object=[obj], session=(sess,))
    assert both.ids == [r["sample_id"] for r in idx
                        if r["object"] == obj and r["session"] == sess]
    state = idx[0]["state"]
    assert ds.slip.where(state=state).ids == [r["sample_id"] for r in idx
                                              if r["state"] == state]
    assert ds.slip.where() .ids == ds.slip.ids
    with pytest.raises(VtsError, match="no slip sample has object") as e:
        ds.slip.where(object="no-such-object")
    one_line(e)
    with pytest.raises(VtsError, match="unknown static index column 'state'"):
        ds.static.where(state="slip")


def test_splits_give_their_parts(ds: loader.VtsDataset, vts_dataset: Path) -> None:
    assert ds.splits, "the test dataset should have split files"
    for name in ds.splits:
        doc = json.loads((vts_dataset / "meta" / "splits" / f"{name}.json").read_text())
        assert set(ds.parts(name)) == set(doc["parts"])
        for part, ids in doc["parts"].items():
            view = ds.split(name, part)
            assert view.kind == doc["kind"]
            assert sorted(view.ids) == sorted(ids)
            whole = ds.view(doc["kind"])
            assert whole.split(name, part).ids == view.ids
            if ids:
                obj = view[0]["object"]
                sub = whole.where(object=obj).split(name, part)
                assert sub.ids == [i for i in view.ids if ds.by_id(i, ())["object"] == obj]


def test_split_errors(ds: loader.VtsDataset) -> None:
    name = ds.splits[0]
    with pytest.raises(VtsError, match="unknown split 'nope'; splits: ") as e:
        ds.split("nope", "train")
    one_line(e)
    with pytest.raises(VtsError, match=f"split '{name}' has no part 'nope'; parts: "):
        ds.split(name, "nope")
    kind = ds.split_file(name).kind
    other = "static" if kind == "slip" else "slip"
    with pytest.raises(VtsError, match=f"is of {kind} samples"):
        ds.view(other).split(name, ds.parts(name)[0])


def test_split_checksum_is_checked_when_read(dataset_copy: Path) -> None:
    ds = vtsbench.load(dataset_copy)
    name = ds.splits[0]
    path = dataset_copy / "meta" / "splits" / f"{name}.json"
    path.write_bytes(path.read_bytes().replace(b'"seed"', b'"seed" ', 1))
    with pytest.raises(VtsError, match="sha256 mismatch") as e:
        ds.split(name, ds_part(path))
    assert str(path) in one_line(e)


def ds_part(path: Path) -> str:
    return next(iter(json.loads(path.read_text())["parts"]))


def test_format_major_version_is_checked(dataset_copy: Path) -> None:
    p = dataset_copy / "meta" / "info.json"
    doc = json.loads(p.read_text())
    doc["format_version"] = "2.0"
    p.write_text(json.dumps(doc))
    with pytest.raises(VtsError, match=r"format_version '2\.0'") as e:
        vtsbench.load(dataset_copy)
    one_line(e)


def test_not_a_dataset(tmp_path: Path) -> None:
    with pytest.raises(VtsError, match="not a vtsbench dataset") as e:
        vtsbench.load(tmp_path)
    one_line(e)
    with pytest.raises(VtsError, match="no such dataset folder"):
        vtsbench.load(tmp_path / "missing")


def test_missing_index_is_an_error(dataset_copy: Path) -> None:
    (dataset_copy / "index" / "slip.parquet").unlink()
    with pytest.raises(VtsError, match="index not found") as e:
        vtsbench.load(dataset_copy)
    assert "slip.parquet" in one_line(e)


def _chunk_reads(monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, object]]:
    """Record every (key, byte range) the local zarr store is asked for."""
    from zarr.storage import LocalStore

    seen: list[tuple[str, object]] = []
    real = LocalStore.get

    async def get(self, key, prototype, byte_range=None):  # type: ignore[no-untyped-def]
        seen.append((key, byte_range))
        return await real(self, key, prototype, byte_range)

    monkeypatch.setattr(LocalStore, "get", get)
    return seen


def test_one_object_reads_only_its_chunks(vts_dataset: Path,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    from zarr.abc.store import RangeByteRequest

    ds = vtsbench.load(vts_dataset)
    obj = ds.slip[0]["object"]
    view = ds.slip.where(object=obj)
    assert len(view) < len(ds.slip), "the test needs more than one object"
    seen = _chunk_reads(monkeypatch)
    view.read(range(len(view)), ("rgb",))
    rgb = [(k, r) for k, r in seen if k.startswith("rgb/c/")]
    ranges = [r for _, r in rgb if isinstance(r, RangeByteRequest)]
    assert len(ranges) == len(view)  # one byte range per sample, nothing else of the data
    assert all(r is not None for _, r in rgb)  # never a whole shard
    assert not any(k.startswith(("depth/", "contact/")) for k, _ in seen)


def test_reads_need_only_their_own_shards(dataset_copy: Path) -> None:
    ds = vtsbench.load(dataset_copy)
    per = ds.info.zarr.samples_per_shard["slip"]
    view = ds.slip
    shard = int(view.rows[0]) // per
    sub = View(ds, "slip", np.flatnonzero(view.rows // per == shard))
    want = sub.read(range(len(sub)), ("rgb", "depth", "contact"))
    group = dataset_copy / "data" / "slip.zarr"
    for name in ("rgb", "depth", "contact"):
        for path in (group / name / "c").iterdir():
            if int(path.name) != shard:
                shutil.rmtree(path)
    (group / "depth" / "c" / str(shard)).rename(group / "depth" / "c" / "moved")
    ds = vtsbench.load(dataset_copy)
    sub = View(ds, "slip", sub._pos)
    got = sub.read(range(len(sub)), ("rgb", "contact"))
    np.testing.assert_array_equal(got["rgb"], want["rgb"])
    np.testing.assert_array_equal(got["contact"], want["contact"])
    with pytest.raises(VtsError, match="missing") as e:  # never zeros for missing data
        sub.read([0], ("depth",))
    assert "slip.zarr/depth/c/" in one_line(e)


def test_views_pickle_without_open_arrays(ds: loader.VtsDataset) -> None:
    view = ds.slip.where(object=ds.slip[0]["object"])
    view[0]
    handles: list[type] = []

    class Spy(pickle.Pickler):
        def reducer_override(self, obj: object) -> object:
            if type(obj).__module__.split(".")[0] in ("zarr", "fsspec", "aiohttp"):
                handles.append(type(obj))
            return NotImplemented

    buf = io.BytesIO()
    Spy(buf).dump(view)
    assert handles == []
    blob = buf.getvalue()
    back = pickle.loads(blob)
    np.testing.assert_array_equal(back[0]["rgb"], view[0]["rgb"])


def test_loading_does_not_import_torch(vts_dataset: Path) -> None:
    code = (
        "import sys, vtsbench\n"
        "assert 'vtsbench.dataset' not in sys.modules\n"
        f"ds = vtsbench.load({str(vts_dataset)!r})\n"
        "s = ds.slip[0]; ds.static[0]; ds.slip.read([0, 1], ('rgb', 'depth'))\n"
        "v = ds.split(ds.splits[0], ds.parts(ds.splits[0])[0])\n"
        "list(ds.static.where(object=ds.static[0]['object']))\n"
        "heavy = [m for m in ('torch', 'transformers', 'datasets') if m in sys.modules]\n"
        "assert not heavy, heavy\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)
