"""View.to_hf: a datasets.IterableDataset streamed from the Zarr store (stored dtypes), or a
datasets.Dataset copy built offline; the Zarr attributes xarray reads."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import vtsbench


@pytest.mark.parametrize("kind", ["static", "slip"])
def test_to_hf_streams_with_stored_dtypes(vts_dataset: Path, tmp_path: Path, kind: str) -> None:
    import datasets

    view = vtsbench.load(vts_dataset).view(kind)[:3]
    hf = view.to_hf()
    assert isinstance(hf, datasets.IterableDataset)
    assert list(hf.features) == [*view.index.column_names, "rgb", "depth", "contact"]
    assert not list(tmp_path.iterdir())  # nothing written
    rows = list(hf)
    assert [r["sample_id"] for r in rows] == view.ids
    for i, r in enumerate(rows):
        s = view[i]
        assert r["rgb"].dtype == np.uint8 and r["depth"].dtype == np.float32
        assert r["contact"].dtype == bool
        for name in ("rgb", "depth", "contact"):
            np.testing.assert_array_equal(r[name], s[name])


@pytest.mark.parametrize("kind", ["static", "slip"])
def test_to_hf_copy(vts_dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                    kind: str) -> None:
    monkeypatch.setenv("HF_DATASETS_OFFLINE", "1")
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    view = vtsbench.load(vts_dataset).view(kind)[:3]
    hf = view.to_hf(copy=True, writer_batch_size=2, cache_dir=tmp_path)
    assert hf.num_rows == len(view)
    assert hf.column_names == [*view.index.column_names, "rgb", "depth", "contact"]
    assert hf["sample_id"] == view.ids
    assert hf.features["rgb"].dtype == "uint8" and hf.features["depth"].dtype == "float32"
    rows = hf.with_format("numpy", dtype=None)  # dtype=None: no widening to int64
    for i in range(len(view)):
        s = view[i]
        r = rows[i]
        assert r["rgb"].dtype == np.uint8 and r["depth"].dtype == np.float32
        assert r["contact"].dtype == bool
        for name in ("rgb", "depth", "contact"):
            np.testing.assert_array_equal(r[name], s[name])
    assert list(Path(tmp_path).rglob("*.arrow"))


def test_hub_arrays_reads_to_hf_rows_as_the_loader(vts_dataset: Path) -> None:
    """hub_arrays, the reader of the Hugging Face copy's rows, gives the loader's arrays of a
    to_hf row too (depth already in mm there), so one reading code serves both."""
    from vtsbench.dataset.read.hf import hub_arrays

    view = vtsbench.load(vts_dataset).slip[:2]
    for i, row in enumerate(view.to_hf()):
        got, s = hub_arrays(row), view[i]
        for name in ("rgb", "depth", "contact"):
            assert got[name].dtype == s[name].dtype and np.array_equal(got[name], s[name])


def test_to_hf_some_arrays_and_empty(vts_dataset: Path, tmp_path: Path) -> None:
    ds = vtsbench.load(vts_dataset)
    hf = ds.slip[:2].to_hf(arrays=("depth",), copy=True, cache_dir=tmp_path)
    assert "rgb" not in hf.column_names and hf.with_format("numpy")[1]["depth"].shape == tuple(
        ds.info.shapes["slip"]["depth"][1:])
    assert ds.slip[:0].to_hf(copy=True, cache_dir=tmp_path).num_rows == 0
    assert list(ds.slip[:0].to_hf()) == []
    assert "rgb" not in next(iter(ds.slip[:1].to_hf(arrays=("depth",))))


def test_xarray_reads_depth_in_mm(vts_dataset: Path) -> None:
    """The CF attributes make xarray decode depth to mm: its maximum is the loader's."""
    xr = pytest.importorskip("xarray")
    ds = vtsbench.load(vts_dataset)
    for kind in ("static", "slip"):
        x = xr.open_zarr(vts_dataset / "data" / f"{kind}.zarr")
        depth = x["depth"].values
        assert x["depth"].attrs["units"] == "mm"
        ref = ds.view(kind).read(slice(None), ("depth",))["depth"]
        assert depth.shape == ref.shape and not np.isnan(depth).any()  # 0 is not masked
        # the same stored count at the maximum: xarray decodes to float64 (the type of
        # scale_factor, CF), count x 0.001; the loader to float32, float32(count) x
        # float32(0.001): equal to within one float32 step (6e-8 mm at 0.9 mm)
        assert round(depth.max() * 1000) == round(float(ref.max()) * 1000) > 50
        assert abs(depth.max() - ref.max()) <= np.spacing(ref.max())
        np.testing.assert_array_equal(np.rint(depth * 1000), np.rint(ref * 1000.0))
        np.testing.assert_allclose(depth, ref, rtol=0, atol=1e-7)
        assert np.array_equal(x["rgb"].values, ds.view(kind).read(slice(None))["rgb"])


def test_format_1_0_datasets_still_load(dataset_copy: Path) -> None:
    """Format 1.1 changed only the depth's Zarr attributes (scale -> CF scale_factor): a 1.0
    dataset loads and verifies as before (the loader takes the scale from info.json)."""
    import json

    from tests.fixtures.damage import depth_attrs_to_1_0
    from vtsbench.dataset.tools.verify import verify

    depth_attrs_to_1_0(dataset_copy)
    info = dataset_copy / "meta" / "info.json"
    doc = json.loads(info.read_text())
    assert doc["format_version"] == "1.1"
    doc.pop("info_sha256")
    doc["format_version"] = "1.0"
    info.write_text(json.dumps(doc))
    ds = vtsbench.load(dataset_copy)
    assert ds.info.format_version == "1.0" and ds.slip[0]["depth"].dtype == np.float32
    assert verify(dataset_copy, decode=False).ok
