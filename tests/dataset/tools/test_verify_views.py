"""`vtsbench verify` and `vtsbench info` on a dataset of format 1.3 (samples as views of the
episode store): intact it checks out; view columns against the episodes, frames outside their
episode, split parts sharing frames, a stray data/static.zarr and damaged frames are each
one line; info says the samples are views of the episodes."""

from __future__ import annotations

import io
import shutil
from pathlib import Path

import pyarrow as pa
from rich.console import Console

from tests.fixtures.damage import rehash, rewrite_index
from tests.fixtures.views import SLIP, STATIC, T
from vtsbench.dataset.format.records import SplitFile
from vtsbench.dataset.splits.files import write_splits
from vtsbench.dataset.tools.info import render, summarise
from vtsbench.dataset.tools.verify import verify


def _set(t: pa.Table, name: str, k: int, value: int) -> pa.Table:
    i = t.column_names.index(name)
    vals = t.column(name).to_pylist()
    vals[k] = value
    return t.set_column(i, t.schema.field(i), pa.array(vals, pa.int64()))


def test_an_intact_views_dataset_verifies(views_dataset: Path) -> None:
    report = verify(views_dataset)
    assert report.ok, report.problems
    assert report.warnings == []
    assert report.samples == len(SLIP) + len(STATIC)
    assert report.shards > 0  # the episode store's shards, decoded


def test_info_says_the_samples_are_views(views_dataset: Path) -> None:
    s = summarise(views_dataset)
    buf = io.StringIO()
    render(s, Console(file=buf, width=300))
    text = buf.getvalue()
    store = s.sizes["data/episodes.zarr"]
    assert (f"samples: views of 3 episodes (frames stored once): {len(STATIC)} static frames "
            f"and {len(SLIP)} slip sequences of {T} read {len(STATIC) + len(SLIP) * T} frames "
            f"from the 42 stored in data/episodes.zarr") in text, text
    assert f"({store} bytes)" in text
    assert s.raw_bytes == 42 * 24 * 32 * 3 + 4 * 42 * 24 * 32  # the store's frames, once


def test_frames_outside_their_episode(views_copy: Path) -> None:
    rewrite_index(views_copy, "static", lambda t: _set(t, "frame_row", 1, 3))  # ep 1: 13..21
    rewrite_index(views_copy, "slip", lambda t: _set(t, "episode_index", 2, 7))
    problems = verify(views_copy, decode=False).problems
    assert problems == [
        "index/static.parquet: frame row outside the sample's episode in 1 row(s) (first: st1 "
        "(row 3, episode 1 holds 13..21))",
        "index/slip.parquet: episode_index is no episode of index/episodes.parquet (3 "
        "episodes) in 1 row(s) (first: sl2 (7))"], problems


def test_negative_and_missing_view_columns(views_copy: Path) -> None:
    rewrite_index(views_copy, "slip", lambda t: _set(t, "frame_row", 0, -2))
    rewrite_index(views_copy, "static", lambda t: t.drop_columns(["episode_index"]))
    problems = verify(views_copy, decode=False).problems
    assert any(p.startswith("index/slip.parquet: frame_row is negative in 1 row(s) (first: "
                            "sl0 (-2))") for p in problems), problems
    assert any(p.startswith("index/static.parquet: no episode_index column, and info.json "
                            "says sample_storage 'episodes'") for p in problems), problems


def test_split_parts_sharing_frames(views_copy: Path) -> None:
    # sl4 (episode 2, frames 0..7) and sl5 (4..11) overlap, sl3 (episode 1) is apart
    sp = SplitFile("leaky", "slip", "overlapping windows apart", 0,
                   {"train": ["sl4", "sl3"], "val": ["sl5"]})
    write_splits(views_copy / "meta" / "splits", [sp])

    def edit(doc: dict) -> None:
        doc["splits"]["leaky"] = sp.sha256()
        doc["counts"]["splits"]["leaky"] = {"train": 2, "val": 1}
        doc["files"]["meta/splits/leaky.json"] = sp.sha256()

    rehash(views_copy, edit)
    problems = verify(views_copy, decode=False).problems
    assert len(problems) == 1 and problems[0].startswith(
        "meta/splits/leaky.json: leak: leaky: samples 'sl4' (train) and 'sl5' (val) share frame "
        "row 26 and 3 more of the episode store"), problems


def test_a_stray_sample_group(views_dataset: Path, views_copy: Path) -> None:
    shutil.copytree(views_dataset / "data" / "episodes.zarr", views_copy / "data" / "slip.zarr")
    problems = verify(views_copy, decode=False).problems
    assert problems[-1] == ("data/slip.zarr: present, and info.json says the slip samples are "
                            "views of the episode store (sample_storage 'episodes')"), problems
    assert all(p.startswith("data/slip.zarr") for p in problems)  # and its files unlisted


def test_a_damaged_frame_names_its_episode(views_copy: Path) -> None:
    shard = sorted((views_copy / "data" / "episodes.zarr" / "rgb" / "c").rglob("*"))
    shard = next(p for p in shard if p.is_file())
    data = bytearray(shard.read_bytes())
    data[40] ^= 0xFF
    shard.write_bytes(bytes(data))
    problems = verify(views_copy).problems
    assert any("sha256 mismatch" in p for p in problems)
    assert any(p.startswith("data/episodes.zarr/rgb: sample episode-000000/0 (row 0)")
               for p in problems), problems
