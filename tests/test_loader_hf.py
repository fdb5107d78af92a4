"""View.to_hf: a datasets.Dataset of index rows plus arrays, built offline."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import vtsbench

pytest_plugins = ["loader_conftest"]


@pytest.mark.parametrize("kind", ["static", "slip"])
def test_to_hf(vts_dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
               kind: str) -> None:
    monkeypatch.setenv("HF_DATASETS_OFFLINE", "1")
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    view = vtsbench.load(vts_dataset).view(kind)[:3]
    hf = view.to_hf(writer_batch_size=2, cache_dir=tmp_path)
    assert hf.num_rows == len(view)
    assert hf.column_names == [*view.index.column_names, "rgb", "depth", "contact"]
    assert hf["sample_id"] == view.ids
    assert hf.features["rgb"].dtype == "uint8" and hf.features["depth"].dtype == "float32"
    rows = hf.with_format("numpy")
    for i in range(len(view)):
        s = view[i]
        r = rows[i]
        # datasets' numpy format widens integers to int64; values are those stored (uint8)
        assert r["depth"].dtype == np.float32 and r["contact"].dtype == bool
        for name in ("rgb", "depth", "contact"):
            np.testing.assert_array_equal(r[name], s[name])
    assert list(Path(tmp_path).rglob("*.arrow"))


def test_to_hf_some_arrays_and_empty(vts_dataset: Path, tmp_path: Path) -> None:
    ds = vtsbench.load(vts_dataset)
    hf = ds.slip[:2].to_hf(arrays=("depth",), cache_dir=tmp_path)
    assert "rgb" not in hf.column_names and hf.with_format("numpy")[1]["depth"].shape == tuple(
        ds.info.shapes["slip"]["depth"][1:])
    assert ds.slip[:0].to_hf(cache_dir=tmp_path).num_rows == 0
