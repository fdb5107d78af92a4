"""Loading through fsspec URLs: a loopback HTTP server with byte ranges, and memory://."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

import vtsbench
from vtsbench.dataset.read.loader import VtsDataset
from vtsbench.errors import VtsError


@pytest.fixture(scope="module")
def local(vts_dataset: Path) -> VtsDataset:
    return vtsbench.load(vts_dataset)


def same_samples(a: VtsDataset, b: VtsDataset) -> None:
    assert a.slip.ids == b.slip.ids and a.static.ids == b.static.ids
    for kind in ("static", "slip"):
        va, vb = a.view(kind), b.view(kind)
        items = [0, len(va) - 1]
        ra = va.read(items, ("rgb", "depth", "contact"))
        rb = vb.read(items, ("rgb", "depth", "contact"))
        for name in ra:
            np.testing.assert_array_equal(ra[name], rb[name])
        assert va[0]["sample_id"] == vb[0]["sample_id"]


def test_http(http_root: str, local: VtsDataset) -> None:
    ds = vtsbench.load(http_root)
    assert ds.location == http_root
    same_samples(ds, local)
    name = ds.splits[0]
    part = ds.parts(name)[0]
    assert ds.split(name, part).ids == local.split(name, part).ids


def test_http_not_a_dataset(http_root: str) -> None:
    with pytest.raises(VtsError, match="not a vtsbench dataset") as e:
        vtsbench.load(http_root + "/index")
    assert "\n" not in str(e.value) and "meta/info.json" in str(e.value)


def test_http_dataloader_workers(http_root: str) -> None:
    torch = pytest.importorskip("torch")
    ds = vtsbench.load(http_root)
    tv = ds.slip.to_torch("rgb", size=(16, 16))
    tv[0]
    loader = torch.utils.data.DataLoader(tv, batch_size=2, num_workers=2, timeout=120)
    ids = [i for _, t in loader for i in t["sample_id"]]
    assert ids == ds.slip.ids


@pytest.fixture
def memory_root(vts_dataset: Path) -> Iterator[str]:
    import fsspec

    fs = fsspec.filesystem("memory")
    fs.put(str(vts_dataset), "/loader-test-ds", recursive=True)
    try:
        yield "memory://loader-test-ds"
    finally:
        fs.rm("/loader-test-ds", recursive=True)


def test_memory(memory_root: str, local: VtsDataset) -> None:
    same_samples(vtsbench.load(memory_root), local)


def test_memory_split_checksum(memory_root: str) -> None:
    import fsspec

    ds = vtsbench.load(memory_root)
    name = ds.splits[0]
    path = f"{memory_root}/meta/splits/{name}.json"
    with fsspec.open(path, "rb") as fh:
        data = fh.read()
    with fsspec.open(path, "wb") as fh:
        fh.write(data.replace(b"{", b"{ ", 1))
    with pytest.raises(VtsError, match="sha256 mismatch") as e:
        ds.split_file(name)
    assert str(e.value).startswith(path + ": ")
