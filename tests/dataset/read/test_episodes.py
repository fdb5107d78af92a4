"""ds.episodes and its windows: by length and stride, by delta_timestamps with padding at both
ends and across dropped frames, never across two episodes; batched reads equal single ones; a
dataset without episodes has none; the loader stays free of torch."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import vtsbench
from tests.fixtures.episodes import FPS, SHARD_MB, take, takes, write_takes
from vtsbench.dataset.read.episodes import delta_windows, length_windows
from vtsbench.errors import VtsError

LENGTHS = (13, 9, 20, 6)


@pytest.fixture(scope="module")
def eps_ds(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Four takes of 13, 9, 20 and 6 frames (rgb, depth, contact), shards of 9 frames."""
    return write_takes(tmp_path_factory.mktemp("episodes") / "ds", takes(depth=True))


@pytest.fixture(scope="module")
def gappy_ds(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One take of 12 frames whose frames 5.. come 2 frame periods late (2 dropped)."""
    out = tmp_path_factory.mktemp("gappy") / "ds"
    with pytest.warns(UserWarning, match="2 dropped"):
        write_takes(out, [take(0, 12, gap=2)])
    return out


def _starts() -> np.ndarray:
    return np.concatenate([[0], np.cumsum(LENGTHS)[:-1]])


@pytest.mark.parametrize(("length", "stride", "pad", "want"), [
    (8, 8, "drop", [(0, 0), (1, 0), (2, 0), (2, 8)]),
    (8, 4, "drop", [(0, 0), (0, 4), (1, 0), (2, 0), (2, 4), (2, 8), (2, 12)]),
    (8, 8, "edge", [(0, 0), (0, 8), (1, 0), (1, 8), (2, 0), (2, 8), (2, 16), (3, 0)]),
    (16, 1, "drop", [(2, s) for s in range(5)]),
])
def test_windows_by_length_and_stride(eps_ds: Path, length, stride, pad, want) -> None:
    ds = vtsbench.load(eps_ds)
    win = ds.episodes.windows(length, stride, pad=pad)
    assert list(zip(win.episode_index.tolist(), win.frame_index[:, 0].tolist(),
                    strict=True)) == want
    lengths = np.array(LENGTHS)[win.episode_index]
    raw = win.frame_index[:, :1] + np.arange(length)
    assert np.array_equal(win.pad_mask, raw >= lengths[:, None])  # padded past the end only
    assert np.array_equal(win.frame_index, np.minimum(raw, lengths[:, None] - 1))
    assert (win.frame_index < lengths[:, None]).all()  # never into the next episode


def test_a_window_holds_its_frames_labels_and_timestamps(eps_ds: Path) -> None:
    ds = vtsbench.load(eps_ds)
    eps = takes(depth=True)
    win = ds.episodes.windows(8, 8, pad="edge", arrays=("rgb", "depth", "contact"))
    for i in range(len(win)):
        w = win[i]
        e, idx = int(w["episode_index"]), w["frame_index"]
        whole = ds.episodes[e]
        assert w["episode_id"] == f"episode-{e:06d}" and w["object"] == eps[e]["object"]
        assert np.array_equal(w["rgb"], eps[e]["frames"][idx])
        assert np.array_equal(w["depth"], whole["depth"][idx])
        assert np.array_equal(w["contact"], eps[e]["contact"][idx])
        assert np.array_equal(w["timestamps"], eps[e]["timestamps"][idx])
        assert np.array_equal(w["state"], whole["state"][idx])
        assert np.array_equal(w["direction"], whole["direction"][idx])
        assert w["force_n"].tolist() == [eps[e]["extra"]["force_n"][k] for k in idx]
    batch = win.read([5, 0, 5, 3], arrays=("rgb", "contact"))  # any order, repeats
    assert batch["rgb"].shape == (4, 8, 24, 32, 3) and set(batch) >= {"pad_mask", "state"}
    for j, i in enumerate([5, 0, 5, 3]):
        assert np.array_equal(batch["rgb"][j], win[i]["rgb"])
        assert np.array_equal(batch["pad_mask"][j], win.pad_mask[i])
        assert batch["episode_id"][j] == win[i]["episode_id"]
    assert sum(1 for _ in win) == len(win)
    assert len(win[2:4]) == 2 and win.read([])["rgb"].shape == (0, 8, 24, 32, 3)


def test_delta_timestamps_pads_at_both_ends(eps_ds: Path) -> None:
    ds = vtsbench.load(eps_ds)
    offsets = [-0.08, -0.04, 0.0, 0.04]  # 2 frames back, 1 ahead
    drop = ds.episodes.windows(delta_timestamps=offsets)
    assert len(drop) == sum(n - 3 for n in LENGTHS)  # anchors 2..n-2
    assert not drop.pad_mask.any()
    assert np.array_equal(drop.frame_index[0], [0, 1, 2, 3])
    edge = ds.episodes.windows(delta_timestamps=offsets, pad="edge")
    assert len(edge) == sum(LENGTHS)  # every frame an anchor
    assert np.array_equal(edge.frame_index[0], [0, 0, 0, 1])
    assert np.array_equal(edge.pad_mask[0], [True, True, False, False])
    last = LENGTHS[0] - 1  # the last anchor of episode 0: its next frame is padded
    assert np.array_equal(edge.frame_index[last], [last - 2, last - 1, last, last])
    assert np.array_equal(edge.pad_mask[last], [False, False, False, True])
    assert (edge.episode_index[LENGTHS[0]], edge.frame_index[LENGTHS[0], 0]) == (1, 0)
    t = ds.episodes[0]["timestamps"]
    assert np.allclose(drop[0]["timestamps"] - t[2], offsets)
    strided = ds.episodes.windows(delta_timestamps=offsets, stride=4)
    assert set(strided.frame_index[:, 2] % 4) == {0}  # anchors every 4th frame
    lerobot = ds.episodes.windows(delta_timestamps=[-0.28 + 0.04 * k for k in range(8)])
    assert len(lerobot) == sum(max(0, n - 7) for n in LENGTHS)
    assert np.array_equal(lerobot.frame_index, np.array(ds.episodes.windows(8, 1)
                                                         .frame_index))


def test_delta_timestamps_across_dropped_frames(gappy_ds: Path) -> None:
    ds = vtsbench.load(gappy_ds)
    ep = ds.episodes[0]
    assert ep["dropped_frames"] == 2
    assert np.allclose(ep["timestamps"][4:7] * FPS, [4, 7, 8])
    # frame 4 is at 4 periods, frame 5 at 7: from anchor 5, 2 and 1 periods back (5 and 6)
    # fall in the gap, and take the nearest frames, 4 and 5, padded
    edge = ds.episodes.windows(delta_timestamps=[-0.08, -0.04, 0.0], pad="edge")
    assert np.array_equal(edge.frame_index[5], [4, 5, 5])
    assert np.array_equal(edge.pad_mask[5], [True, True, False])
    drop = ds.episodes.windows(delta_timestamps=[-0.08, -0.04, 0.0])
    assert 5 not in drop.frame_index[:, 2] and 6 not in drop.frame_index[:, 2]
    assert 7 in drop.frame_index[:, 2]
    assert len(ds.episodes.windows(4, 1)) == 9  # frame counts, not time


def test_window_helpers_on_their_own() -> None:
    ep, idx, pad = length_windows(np.array([3, 0, 5]), 4, 2, "edge")
    assert ep.tolist() == [0, 0, 2, 2, 2]
    assert idx.tolist()[1] == [2, 2, 2, 2] and pad.tolist()[1] == [False, True, True, True]
    ts = np.array([0.0, 0.1, 0.2, 10.0, 10.1])
    ep, idx, pad = delta_windows(ts, np.array([0, 3]), np.array([3, 2]), np.array([10.0, 10.0]),
                                 np.array([-0.1, 0.0]), 1, "drop")
    assert ep.tolist() == [0, 0, 1] and idx.tolist() == [[0, 1], [1, 2], [0, 1]]
    _, idx, pad = delta_windows(ts[:3], np.array([0]), np.array([3]), np.array([10.0]),
                                np.array([0.05]), 1, "edge")  # half-way: the earlier frame
    assert (idx[0, 0], pad[0, 0], idx[2, 0], pad[2, 0]) == (0, False, 2, False)
    _, idx, pad = delta_windows(ts[:3], np.array([0]), np.array([3]), np.array([10.0]),
                                np.array([0.06]), 1, "edge")  # past half a period: padded
    assert (idx[2, 0], pad[2, 0], pad[0, 0]) == (2, True, False)


def test_episode_views_and_bad_window_arguments(eps_ds: Path) -> None:
    ds = vtsbench.load(eps_ds)
    mugs = ds.episodes.where(object="mug")
    assert mugs.ids == ["episode-000000", "episode-000003"]
    assert len(mugs.windows(8, 8)) == 1  # episode 3 has 6 frames
    assert len(ds.episodes[1:3]) == 2 and len(ds.episodes[1:3].frames) == 29
    assert ds.episodes.where(trial="2").ids == ["episode-000002"]
    with pytest.raises(VtsError, match="unknown episode column 'colour'"):
        ds.episodes.where(colour="red")
    for kw, msg in (({"length": 0}, "length must be"), ({"pad": "zero"}, "pad must be"),
                    ({"stride": 0}, "stride must be"),
                    ({"delta_timestamps": [float("nan")]}, "finite"),
                    ({"delta_timestamps": []}, "1..100000"),
                    ({"arrays": ("flow",)}, "unknown array 'flow'")):
        with pytest.raises(VtsError, match=msg):
            ds.episodes.windows(**kw)
    with pytest.raises(IndexError, match="out of range"):
        ds.episodes[4]
    with pytest.raises(IndexError, match="out of range"):
        ds.episodes.windows(8, 8)[99]


def test_rgb_only_dataset_refuses_depth(tmp_path: Path) -> None:
    ds = vtsbench.load(write_takes(tmp_path / "ds", takes()[:1]))
    with pytest.raises(VtsError, match="needs the depth array"):
        ds.episodes.windows(8, arrays=("rgb", "depth"))
    assert set(ds.episodes[0]) & {"depth", "contact"} == set()


def test_a_dataset_of_format_1_1_loads_as_before_with_no_episodes(vts_dataset: Path) -> None:
    ds = vtsbench.load(vts_dataset)
    assert ds.info.format_version == "1.1" and ds.info.episodes is None
    assert "episodes" not in (vts_dataset / "meta" / "info.json").read_text()
    assert len(ds.episodes) == 0 and len(ds.episodes.windows(8, 8)) == 0
    assert len(ds.episodes.windows(delta_timestamps=[0.0])) == 0
    assert len(ds.slip) > 0 and ds.slip[0]["rgb"].shape[0] == 8


def test_loading_and_windows_never_import_torch(eps_ds: Path) -> None:
    code = ("import sys, vtsbench; ds = vtsbench.load(sys.argv[1]); "
            "w = ds.episodes.windows(8, 1); w.read([0, 1]); "
            "ds.episodes.windows(delta_timestamps=[-0.04, 0.0])[0]; "
            "print('torch' in sys.modules)")
    res = subprocess.run([sys.executable, "-c", code, str(eps_ds)], capture_output=True,
                         text=True)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.strip() == "False"


def test_episodes_pickle_for_workers(eps_ds: Path) -> None:
    import pickle

    win = vtsbench.load(eps_ds).episodes.windows(8, 4)
    win[0]  # opens the store in this process
    again = pickle.loads(pickle.dumps(win))
    assert np.array_equal(again[3]["rgb"], win[3]["rgb"])


def test_a_damaged_index_is_refused_on_load(tmp_path: Path) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    from tests.fixtures.damage import rehash

    out = write_takes(tmp_path / "ds", takes()[:2])
    path = out / "index" / "frames.parquet"
    t = pq.read_table(path)
    ts = t.column("timestamp").to_numpy().copy()
    ts[3] = ts[2]
    pq.write_table(t.set_column(2, t.schema.field(2), pa.array(ts)), path)
    rehash(out)
    with pytest.raises(VtsError) as err:
        vtsbench.load(out)
    assert "timestamp not after the previous frame's in 1 row(s) (first: episode-000000/3" \
        in str(err.value) and "index/episodes.parquet" in str(err.value)


def test_shard_size_does_not_change_what_is_read(tmp_path: Path) -> None:
    a = vtsbench.load(write_takes(tmp_path / "a", takes()[:3]))
    b = vtsbench.load(write_takes(tmp_path / "b", takes()[:3], shard_mb=SHARD_MB * 20))
    wa, wb = a.episodes.windows(5, 3), b.episodes.windows(5, 3)
    assert np.array_equal(wa.read(slice(None))["rgb"], wb.read(slice(None))["rgb"])


def test_episodes_read_from_a_url(eps_ds: Path) -> None:
    import fsspec

    from vtsbench.dataset.tools.info import summarise

    mem = fsspec.filesystem("memory")
    mem.put(str(eps_ds), "/episodes-remote", recursive=True)
    try:
        remote = vtsbench.load("memory://episodes-remote")
        local = vtsbench.load(eps_ds)
        rw, lw = remote.episodes.windows(8, 4), local.episodes.windows(8, 4)
        assert len(rw) == len(lw)
        got, want = rw.read([0, 3], ("rgb", "depth")), lw.read([0, 3], ("rgb", "depth"))
        assert all(np.array_equal(got[k], want[k]) for k in ("rgb", "depth", "timestamps"))
        assert summarise("memory://episodes-remote").by_object["mug"]["episodes"] == 2
    finally:
        mem.rm("/episodes-remote", recursive=True)
