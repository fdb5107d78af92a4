"""Format 1.3: the static frames and slip sequences are views of the episode store. Every way
of reading samples (View.read with frames, shuffled and repeated positions, iteration, where,
split, to_torch, to_hf, the training cache, a pickled view) gives the frames the episodes hold,
bit for bit; the loader refuses frames outside their episode and splits sharing frames, in
one line; datasets of the earlier formats load unchanged."""

from __future__ import annotations

import json
import pickle
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

import vtsbench
from tests.fixtures.damage import rehash, rewrite_index
from tests.fixtures.episodes import take, takes, write_takes
from tests.fixtures.serve import serve
from tests.fixtures.views import SLIP, STATIC, T
from vtsbench.dataset.format.records import SplitFile
from vtsbench.dataset.splits.files import write_splits
from vtsbench.dataset.tools.hub import export_hf
from vtsbench.errors import VtsError

ARRAYS = ("rgb", "depth", "contact")


def frames_of(ds, episode: int, start: int, n: int) -> dict[str, np.ndarray]:
    """Frames start..start+n-1 of an episode, read through ds.episodes."""
    ep = ds.episodes.episode(episode, ARRAYS)
    return {a: ep[a][start:start + n] for a in ARRAYS}


def test_samples_are_the_episodes_frames(views_dataset: Path) -> None:
    ds = vtsbench.load(views_dataset)
    assert ds.info.views and ds.info.format_version == "1.3"
    assert not (views_dataset / "data" / "static.zarr").exists()
    assert not (views_dataset / "data" / "slip.zarr").exists()
    assert (len(ds.slip), len(ds.static)) == (len(SLIP), len(STATIC))
    for i, (ep, start, _) in enumerate(SLIP):
        s = ds.slip[i]
        want = frames_of(ds, ep, start, T)
        assert s["sample_id"] == f"sl{i}" and s["rgb"].shape == (T, 24, 32, 3)
        for a in ARRAYS:
            assert s[a].dtype == want[a].dtype and np.array_equal(s[a], want[a]), (i, a)
        raw = take(ep, (13, 9, 20)[ep], depth=True)
        assert np.array_equal(s["rgb"], raw["frames"][start:start + T])
        assert np.allclose(s["depth"], raw["depth"][start:start + T], atol=5e-4)
        assert s["depth"].dtype == np.float32
    for i, (ep, frame) in enumerate(STATIC):
        s = ds.static[i]
        want = frames_of(ds, ep, frame, 1)
        assert s["rgb"].shape == (24, 32, 3)
        for a in ARRAYS:
            assert np.array_equal(s[a], want[a][0]), (i, a)
    idx = ds.slip.index
    assert idx.column("episode_index").to_pylist() == [e for e, _, _ in SLIP]
    starts = ds.episodes.index.column("frame_start").to_numpy()
    assert idx.column("frame_row").to_pylist() == [int(starts[e]) + s for e, s, _ in SLIP]


def test_read_with_frames_shuffled_and_repeated(views_dataset: Path) -> None:
    ds = vtsbench.load(views_dataset)
    whole = ds.slip.read(slice(None), ARRAYS)
    assert whole["rgb"].shape == (len(SLIP), T, 24, 32, 3)
    some = ds.slip.read(slice(None), ARRAYS, frames=[7, 0, 3, 3])
    for a in ARRAYS:
        assert np.array_equal(some[a], whole[a][:, [7, 0, 3, 3]])
    order = [6, 1, 1, 0, 7, 2, 1]
    got = ds.slip.read(order, ARRAYS)
    for a in ARRAYS:
        assert np.array_equal(got[a], whole[a][order])
        assert np.array_equal(got[a][3], ds.slip.sample(0, (a,))[a])
    st = ds.static.read([4, 0, 4, 2], ("rgb", "depth"))
    assert st["rgb"].shape == (4, 24, 32, 3) and st["depth"].shape == (4, 24, 32)
    assert np.array_equal(st["depth"][0], ds.static[4]["depth"])
    empty = ds.slip.read([], ("rgb",), frames=[0, 1])
    assert empty["rgb"].shape == (0, 2, 24, 32, 3)
    with pytest.raises(VtsError, match="frames apply to slip sequences only"):
        ds.static.read([0], frames=[0])


def test_iteration_where_split_and_pickling(views_dataset: Path) -> None:
    ds = vtsbench.load(views_dataset)
    items = list(ds.slip)
    assert [s["sample_id"] for s in items] == ds.slip.ids
    for i, s in enumerate(items):
        assert np.array_equal(s["depth"], ds.slip[i]["depth"])
    mug = ds.slip.where(object="mug")
    assert mug.ids == ["sl0", "sl1", "sl2"]
    assert np.array_equal(mug.read([2])["rgb"][0], ds.slip[2]["rgb"])
    assert np.array_equal(ds.slip.by_id("sl5")["contact"], ds.slip[5]["contact"])
    sample_splits = [n for n in ds.splits if ds.split_file(n).kind in ("static", "slip")]
    assert sample_splits, ds.splits
    for name in sample_splits:
        for part in ds.parts(name):
            view = ds.split(name, part)
            if len(view):
                assert np.array_equal(view.read([0])["rgb"][0],
                                      ds.by_id(view.ids[0])["rgb"])
    view = pickle.loads(pickle.dumps(ds.slip[2:5]))
    assert np.array_equal(view.read(slice(None), ("depth",))["depth"],
                          ds.slip.read([2, 3, 4], ("depth",))["depth"])


def test_to_torch_to_hf_and_the_cache(views_dataset: Path) -> None:
    torch = pytest.importorskip("torch")
    ds = vtsbench.load(views_dataset)
    tv = ds.slip.to_torch("rgbd", targets=("contact",))
    x, y = tv[3]
    ep, start, _ = SLIP[3]
    want = frames_of(ds, ep, start, T)
    assert torch.equal(x["rgb"], torch.from_numpy(want["rgb"]).permute(0, 3, 1, 2))
    assert torch.equal(x["depth"][:, 0], torch.from_numpy(want["depth"]))
    assert torch.equal(y["contact"], torch.from_numpy(want["contact"]))
    batch = tv.__getitems__([5, 0, 5])
    assert torch.equal(batch[0][0]["rgb"], batch[2][0]["rgb"])
    assert torch.equal(batch[1][0]["rgb"], tv[0][0]["rgb"])
    small = ds.static.to_torch("rgb", size=(12, 16))
    assert tuple(small[1][0].shape) == (3, 12, 16)
    pytest.importorskip("datasets")
    rows = list(ds.static.to_hf(("rgb",)))
    assert [r["sample_id"] for r in rows] == ds.static.ids
    assert np.array_equal(np.asarray(rows[2]["rgb"], np.uint8), ds.static[2]["rgb"])
    from vtsbench.transforms.cache import read_samples

    got = read_samples(ds.slip, [4, 1], ("rgb",))
    assert np.array_equal(got[0]["rgb"], ds.slip[4]["rgb"])


def test_no_group_of_their_own(views_dataset: Path) -> None:
    ds = vtsbench.load(views_dataset)
    with pytest.raises(VtsError, match=r"views of the episode store .*no data/slip\.zarr"):
        ds._kinds["slip"].array("rgb")


def _add_split(ds: Path, split: SplitFile) -> None:
    write_splits(ds / "meta" / "splits", [split])

    def edit(doc: dict) -> None:
        doc["splits"][split.name] = split.sha256()
        doc["counts"]["splits"][split.name] = {p: len(v) for p, v in split.parts.items()}
        doc["files"][f"meta/splits/{split.name}.json"] = split.sha256()

    rehash(ds, edit)


def test_a_split_sharing_frames_is_refused(views_copy: Path) -> None:
    # sl0 holds frames 0..7 of episode 0, sl1 frames 3..10: apart by id, one take's frames
    _add_split(views_copy, SplitFile("leaky", "slip", "overlapping windows apart", 0,
                                     {"train": ["sl0", "sl4"], "test": ["sl1"]}))
    ds = vtsbench.load(views_copy)
    with pytest.raises(VtsError) as e:
        ds.split("leaky", "train")
    msg = str(e.value)
    assert "\n" not in msg and "meta/splits/leaky.json" in msg
    assert ("leak: samples 'sl0' (train) and 'sl1' (test) share frame row 3 and 4 more of "
            "the episode store") in msg, msg
    loose = vtsbench.load(views_copy, allow_leaks=True)
    assert loose.split("leaky", "train").ids == ["sl0", "sl4"]


def test_frames_outside_their_episode_are_refused(views_copy: Path) -> None:
    # sl0 of episode 0 (frames 0..12) moved to rows 10..17: into episode 1
    def move(t: pa.Table) -> pa.Table:
        i = t.column_names.index("frame_row")
        rows = t.column("frame_row").to_pylist()
        rows[0] = 10
        return t.set_column(i, t.schema.field(i), pa.array(rows, pa.int64()))

    rewrite_index(views_copy, "slip", move)
    with pytest.raises(VtsError) as e:
        vtsbench.load(views_copy)
    msg = str(e.value)
    assert "\n" not in msg and "index/slip.parquet" in msg
    assert ("frame rows outside the sample's episode in 1 row(s) (first: sl0 (rows 10..17, "
            "episode 0 holds 0..12))") in msg, msg


def test_view_columns_are_required(views_copy: Path) -> None:
    rewrite_index(views_copy, "static", lambda t: t.drop_columns(["frame_row"]))
    with pytest.raises(VtsError, match=r"index/static\.parquet: no frame_row column, and "
                                       r"info\.json says sample_storage 'episodes'"):
        vtsbench.load(views_copy)


def test_earlier_formats_load_unchanged(vts_dataset: Path, tmp_path: Path) -> None:
    from vtsbench.dataset.tools.verify import verify

    doc = json.loads((vts_dataset / "meta" / "info.json").read_text())
    assert "sample_storage" not in doc and doc["format_version"] == "1.1"
    old = vtsbench.load(vts_dataset)
    assert not old.info.views and old._kinds["slip"].frame_row is None
    assert old.slip[0]["rgb"].shape[0] == old.info.frames_per_sequence
    assert verify(vts_dataset, decode=False).ok
    eps = write_takes(tmp_path / "eps", takes(depth=True))
    doc = json.loads((eps / "meta" / "info.json").read_text())
    assert "sample_storage" not in doc and doc["format_version"] == "1.2"
    ds = vtsbench.load(eps)
    assert len(ds.slip) == 0 and len(ds.episodes) == 4 and not ds.info.views
    report = verify(eps)
    assert report.ok, report.problems


def test_over_http_and_to_the_hub(views_dataset: Path, tmp_path: Path) -> None:
    local = vtsbench.load(views_dataset)
    with serve(views_dataset) as url:
        ds = vtsbench.load(url)
        assert ds.info.views
        got = ds.slip.read([6, 2], ARRAYS)
        want = local.slip.read([6, 2], ARRAYS)
        for a in ARRAYS:
            assert np.array_equal(got[a], want[a])
    copy = Path(shutil.copytree(views_dataset, tmp_path / "copy"))
    layout = export_hf(copy).layout
    assert sum(f.rows for f in layout.files["slip"]) == len(SLIP)
    assert sum(f.rows for f in layout.files["static"]) == len(STATIC)
