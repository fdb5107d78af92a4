"""vtsbench verify: a flipped byte names its array and sample; missing files, tampered and leaky
split files; exit 1 on any problem."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from vtsbench.cli import app
from vtsbench.dataset.format.arrays import Layout
from vtsbench.dataset.format.index import read_metas as read_index
from vtsbench.dataset.tools.verify import chunk_of_byte, shard_index, verify


def _flip(path: Path, offset: int) -> None:
    data = bytearray(path.read_bytes())
    data[offset] ^= 0x5A
    path.write_bytes(bytes(data))


def test_intact_dataset_verifies(built: Path) -> None:
    report = verify(built)
    assert report.ok, report.problems
    assert report.samples == 15 and report.shards == 3 * 11


@pytest.mark.parametrize("kind, name, row", [("slip", "rgb", 3), ("static", "depth", 5),
                                             ("static", "contact", 1)])
def test_flipped_byte_names_array_and_sample(ds: Path, kind: str, name: str, row: int) -> None:
    info = json.loads((ds / "meta/info.json").read_text())
    sps = info["zarr"]["samples_per_shard"][kind]
    shape = info["shapes"][kind][name]
    lay = Layout(kind, shape[0], (96, 128), 8 if kind == "slip" else None, sps, 3)
    k, j = divmod(row, sps)
    shard = ds / "data" / f"{kind}.zarr" / lay.shard_key(name, k)
    data = shard.read_bytes()
    idx, ok = shard_index(data, sps)
    assert ok
    offset = int(idx[j, 0]) + int(idx[j, 1]) // 2  # a byte in the middle of the sample's chunk
    assert chunk_of_byte(data, sps, offset) == j
    _flip(shard, offset)
    sid = read_index(ds / "index" / f"{kind}.parquet", kind)[row].sample_id
    res = CliRunner().invoke(app, ["verify", str(ds)], terminal_width=300)
    assert res.exit_code == 1
    key = lay.shard_key(name, k).removeprefix(f"{name}/")
    want = (f"data/{kind}.zarr/{name}: sample {sid} (row {row}): shard {key} fails to decode "
            "(crc32c mismatch)")
    assert want in res.output, res.output
    assert f"data/{kind}.zarr/{lay.shard_key(name, k)}: sha256 mismatch" in res.output


def test_damaged_shard_index_names_the_samples_of_the_shard(ds: Path) -> None:
    shard = ds / "data/static.zarr/rgb/c/0/0/0/0"
    _flip(shard, shard.stat().st_size - 10)
    problems = verify(ds).problems
    assert ("data/static.zarr/rgb: samples static-00001..static-00004 (rows 0-3, the whole "
            "shard): shard c/0/0/0/0 fails to decode (its index fails its crc32c)") in problems


def test_missing_and_unlisted_files(ds: Path) -> None:
    (ds / "data/slip.zarr/depth/c/2/0/0/0").unlink()
    (ds / "index/extra.txt").write_text("x")
    problems = verify(ds).problems
    assert "data/slip.zarr/depth/c/2/0/0/0: missing" in problems
    assert "index/extra.txt: not listed in meta/info.json" in problems
    assert any(p.startswith("data/slip.zarr/depth: sample seq-00003 (row 2): shard c/2/0/0/0 is "
                            "missing") for p in problems)


def test_tampered_split_file(ds: Path) -> None:
    path = ds / "meta/splits/seen.json"
    doc = json.loads(path.read_text())
    doc["description"] += " (edited)"
    path.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
    problems = verify(ds, decode=False).problems
    assert any(p.startswith("meta/splits/seen.json: sha256 mismatch") for p in problems)


def test_leaky_split(ds: Path) -> None:
    path = ds / "meta/splits/unseen_objects.json"
    doc = json.loads(path.read_text())
    leaked = doc["parts"]["train"][0]  # a seen object's sample also in the unseen test part
    doc["parts"]["test"] = sorted([*doc["parts"]["test"], leaked])
    path.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
    obj = next(m.object for m in read_index(ds / "index/slip.parquet", "slip")
               if m.sample_id == leaked)
    problems = verify(ds, decode=False).problems
    where = "meta/splits/unseen_objects.json: leak: unseen_objects"
    assert f"{where}: object {obj!r} in both train and test" in problems, problems
    assert f"{where}: sample {leaked!r} in both train and test" in problems


def test_not_a_dataset(tmp_path: Path) -> None:
    res = CliRunner().invoke(app, ["verify", str(tmp_path)])
    assert res.exit_code == 1 and "not a vtsbench dataset" in res.output
