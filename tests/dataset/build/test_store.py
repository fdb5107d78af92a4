"""Zarr storage: depth scale and clipping, whole-shard encoding, metadata, path or URL reads."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from vtsbench.dataset.build.store import (
    encode_shard,
    encode_shard_zarr,
    samples_per_shard,
    write_metadata,
    write_shard,
)
from vtsbench.dataset.format.arrays import DEPTH_MAX_MM, Layout, depth_to_int16, depth_to_mm
from vtsbench.dataset.format.layout import ARRAYS
from vtsbench.dataset.format.layout import STORED_DTYPES as DTYPES
from vtsbench.dataset.read.store import open_group
from vtsbench.errors import VtsError


def test_depth_int16_scale_rounding_and_clipping() -> None:
    mm = np.array([0.0, 0.0004, 0.0006, -0.0015, 1.2345, 40.0, -40.0, np.nan, np.inf], np.float32)
    got = depth_to_int16(mm)
    assert got.dtype == np.int16
    assert got.tolist() == [0, 0, 1, -2, 1234, 32767, -32768, 0, 32767]
    back = depth_to_mm(got)
    assert back.dtype == np.float32
    assert np.allclose(back[:5], [0, 0, 0.001, -0.002, 1.234], atol=1e-7)
    assert abs(back[5] - DEPTH_MAX_MM) < 1e-5
    x = np.random.default_rng(0).uniform(-3, 3, 1000).astype(np.float32)
    assert np.abs(depth_to_mm(depth_to_int16(x)) - x).max() <= 0.0005 + 1e-6  # half a step


def test_samples_per_shard() -> None:
    assert samples_per_shard((480, 640), None) == 36  # 32 MiB of 921,600-byte frames
    assert samples_per_shard((480, 640), 8) == 4
    assert samples_per_shard((480, 640), 8, 1000) == 1  # never less than one sample


def _data(lay: Layout, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    out = {n: rng.integers(0, 3, lay.shape(n)).astype(DTYPES[n]) for n in ARRAYS}
    out["contact"][0] = False  # an all-fill-value chunk is still written
    return out


@pytest.mark.parametrize("level", [0, 3])
def test_whole_shards_read_back_by_path_and_url(tmp_path: Path, level: int) -> None:
    lay = Layout("slip", 5, (6, 8), 3, 2, level)
    group = tmp_path / "data" / "slip.zarr"
    write_metadata(group, lay)
    data = _data(lay)
    for k in range(lay.n_shards):
        r = lay.shard_rows(k)
        write_shard(group, lay, k, {n: data[n][r.start:r.stop] for n in ARRAYS})
    assert lay.n_shards == 3 and list(lay.shard_rows(2)) == [4]
    for root in (tmp_path, tmp_path.as_uri()):
        g = open_group(root, "slip")
        for n in ARRAYS:
            assert g[n].shape == lay.shape(n) and str(g[n].dtype) == DTYPES[n]
            assert g[n].chunks == (1, *lay.sample_shape(n))
            assert g[n].shards == (2, *lay.sample_shape(n))
            assert np.array_equal(g[n][:], data[n])
    meta = json.loads((group / "zarr.json").read_text())
    attrs = meta["consolidated_metadata"]["metadata"]["depth"]["attributes"]
    # CF attributes: xarray and other CF readers give mm; no _FillValue (0 is a valid depth)
    assert attrs["scale_factor"] == 0.001 and attrs["units"] == "mm" and "_FillValue" not in attrs
    # rewriting the metadata leaves the shards alone
    write_metadata(group, lay)
    assert np.array_equal(open_group(tmp_path, "slip")["rgb"][:], data["rgb"])
    names = sorted(p.name for p in group.rglob("*") if p.name.startswith("."))
    assert names == []  # no temporary left behind


def test_encoding_is_deterministic_and_checks_the_block() -> None:
    lay = Layout("static", 4, (6, 8), None, 4, 3)
    block = _data(lay)["rgb"][:3]
    assert encode_shard(lay, "rgb", block) == encode_shard(lay, "rgb", block.copy())
    with pytest.raises(ValueError, match="shard block"):
        encode_shard(lay, "rgb", block[:, :, :4])
    with pytest.raises(ValueError, match="shard block"):
        encode_shard(lay, "rgb", np.concatenate([block, block]))


@pytest.mark.parametrize("level", [0, 1, 3])
@pytest.mark.parametrize(("kind", "frames", "sps"), [("static", None, 4), ("slip", 3, 2),
                                                     ("slip", 1, 1)])
def test_shards_are_the_bytes_zarr_writes(level: int, kind: str, frames: int | None,
                                          sps: int) -> None:
    lay = Layout(kind, 5, (6, 8), frames, sps, level)
    data = _data(lay, seed=level)
    data["depth"][-1] = 0  # a chunk of fill values is still written
    for name in ARRAYS:
        for rows in {1, sps}:  # a full shard and a partial last one
            block = data[name][:rows]
            assert encode_shard(lay, name, block) == encode_shard_zarr(lay, name, block)


def test_missing_group_is_one_line(tmp_path: Path) -> None:
    with pytest.raises(VtsError, match="no such Zarr group"):
        open_group(tmp_path, "static")
    with pytest.raises(ValueError):
        open_group(tmp_path, "other")
