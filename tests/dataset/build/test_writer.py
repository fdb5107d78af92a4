"""vtsbench.create: episodes written frame by frame or whole, read back exactly; every bad input
one line naming the episode and frame; dropped frames counted; the finish and context rules."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import vtsbench
from tests.fixtures.datasets import tree_bytes
from tests.fixtures.episodes import FPS, SHARD_MB, SIZE, take, takes, write_takes
from vtsbench.dataset.build.writer import DroppedFramesWarning
from vtsbench.dataset.format.arrays import depth_to_int16, depth_to_mm
from vtsbench.errors import VtsError


@pytest.mark.parametrize("depth", [False, True], ids=["rgb", "rgbd"])
def test_round_trip_is_exact(tmp_path: Path, depth: bool) -> None:
    eps = takes(depth)
    write_takes(tmp_path / "ds", eps, name="takes", calibration_sha256="ab" * 32)
    ds = vtsbench.load(tmp_path / "ds")
    assert ds.info.format_version == "1.2" and len(ds.static) == len(ds.slip) == 0
    assert len(ds.episodes) == 4 and ds.episodes.ids == [f"episode-{k:06d}" for k in range(4)]
    start = 0
    for k, ep in enumerate(eps):
        got = ds.episodes[k]
        n = len(ep["frames"])
        assert got["episode_index"] == k and got["length"] == n
        assert got["frame_start"] == start and got["object"] == ep["object"]
        assert got["session"] == ep["session"] and got["sensor"] == "gelsight-mini"
        assert got["trial"] == str(k) and got["calibration_sha256"] == "ab" * 32
        assert got["fps"] == FPS and got["dropped_frames"] == 0
        assert got["duration_s"] == pytest.approx(n / FPS)
        assert np.array_equal(got["rgb"], ep["frames"]) and got["rgb"].dtype == np.uint8
        assert got["timestamps"].dtype == np.float64
        assert np.array_equal(got["timestamps"], ep["timestamps"])  # bit for bit
        assert np.array_equal(got["frame_index"], np.arange(n))
        assert got["state"].tolist() == [0, 0, 1, 1] + [2] * (n - 4)
        assert got["direction"].tolist() == [-1] * 4 + ep["directions"][4:]
        assert got["force_n"].tolist() == ep["extra"]["force_n"]
        assert got["marker"].tolist() == ep["extra"]["marker"]
        if depth:
            want = depth_to_mm(depth_to_int16(ep["depth"]))
            assert np.array_equal(got["depth"], want) and got["depth"].dtype == np.float32
            assert np.array_equal(got["contact"], ep["contact"])
        else:
            assert set(got) & {"depth", "contact"} == set()
        start += n
    assert ds.info.episodes is not None and ds.info.episodes.frames == start


def test_frame_by_frame_gives_the_same_bytes_as_whole_episodes(tmp_path: Path) -> None:
    eps = takes()
    write_takes(tmp_path / "a", eps, name="same")
    with vtsbench.create(tmp_path / "b", fps=FPS, shard_mb=SHARD_MB, sensor="gelsight-mini",
                         name="same") as w:
        for ep in eps:
            for i in range(len(ep["frames"])):
                w.add_frame(ep["frames"][i], timestamp=ep["timestamps"][i],
                            state=ep["states"][i], direction=ep["directions"][i],
                            **{k: v[i] for k, v in ep["extra"].items()})
            assert w.pending == len(ep["frames"])
            w.save_episode(object=ep["object"], session=ep["session"], trial=ep["trial"])
    assert tree_bytes(tmp_path / "a") == tree_bytes(tmp_path / "b")


def test_timestamps_default_to_frame_over_fps_and_gaps_are_counted(tmp_path: Path) -> None:
    plain = take(0, 12)
    del plain["timestamps"]
    gappy = take(1, 12, gap=3)  # frames 5.. come 3 frame periods late
    with vtsbench.create(tmp_path / "ds", fps=FPS, shard_mb=SHARD_MB) as w:
        w.add_episode(**plain)
        with pytest.warns(DroppedFramesWarning, match=r"episode 1 .*3 dropped frame\(s\).*after "
                                                      r"frame 4"):
            w.add_episode(**gappy)
    ds = vtsbench.load(tmp_path / "ds")
    assert np.array_equal(ds.episodes[0]["timestamps"], np.arange(12) / FPS)
    assert ds.episodes.index.column("dropped_frames").to_pylist() == [0, 3]
    assert ds.info.episodes is not None and ds.info.episodes.dropped_frames == 3
    assert ds.episodes[1]["duration_s"] == pytest.approx(15 / FPS)


def _one_line(err: pytest.ExceptionInfo[VtsError], *parts: str) -> None:
    text = str(err.value)
    assert "\n" not in text, text
    for p in parts:
        assert p in text, text


def _writer(tmp_path: Path, **kw) -> vtsbench.dataset.build.writer.EpisodeWriter:
    return vtsbench.create(tmp_path / "ds", fps=FPS, shard_mb=SHARD_MB, **kw)


RGB = np.zeros((*SIZE, 3), np.uint8)


@pytest.mark.parametrize(("first", "bad", "parts"), [
    ({}, {"timestamp": 0.0}, ("frame 1", "repeats", "strictly increasing")),
    ({"timestamp": 0.5}, {"timestamp": 0.2}, ("frame 1", "goes back")),
    (None, {"timestamp": float("nan")}, ("frame 0", "not finite")),
    (None, {"timestamp": float("inf")}, ("frame 0", "not finite")),
    (None, {"timestamp": -1.0}, ("frame 0", "negative")),
    ({}, {"timestamp": None}, ("frame 1", "no timestamp")),
    ({}, {"rgb": np.zeros((12, 32, 3), np.uint8)}, ("frame 1", "size 12x32", "24x32")),
    ({}, {"rgb": np.zeros((*SIZE, 4), np.uint8)}, ("frame 1", "4 channels", "expected 3")),
    ({}, {"rgb": np.zeros(SIZE, np.uint8)}, ("frame 1", "(H, W, 3)")),
    ({}, {"rgb": np.zeros((*SIZE, 3), np.float32)}, ("frame 1", "float32", "uint8")),
    ({}, {"state": "sliding"}, ("frame 1", "state 'sliding'")),
    ({}, {"state": 3}, ("frame 1", "state 3")),
    ({}, {"state": "slip", "direction": 8}, ("frame 1", "direction 8", "0..7")),
    ({}, {"state": "press", "direction": 2}, ("frame 1", "not slip")),
    ({}, {"depth": np.zeros(SIZE)}, ("frame 1", "depth given", "arrays=('rgb',)")),
    ({}, {"timestamp": 1.0, "rgb_extra": [1]}, ("frame 1", "rgb_extra", "list")),
    ({}, {"timestamp": 1.0, "Bad-Name": 1}, ("frame 1", "not a plain lowercase name")),
    ({}, {"timestamp": 1.0, "state_x": "a", "timestamps": 1}, ("frame 1", "'timestamps'",
                                                               "taken by the format")),
])
def test_bad_frame_is_one_line_naming_it(tmp_path: Path, first, bad, parts) -> None:
    with _writer(tmp_path) as w:
        try:
            if first is not None:
                w.add_frame(RGB, **{"timestamp": 0.0, "state": "slip", "direction": 1,
                                    **first})
            args = {"rgb": RGB, "timestamp": 0.04, **bad}
            with pytest.raises(VtsError) as err:
                w.add_frame(args.pop("rgb"), **args)
            _one_line(err, "episode 0", *parts)
            assert w.pending == (0 if first is None else 1)  # a refused frame is not kept
        finally:
            w.discard_episode()
            w.close()


@pytest.mark.parametrize(("depth", "parts"), [
    (np.full(SIZE, np.nan, np.float32), ("frame 0", "768 NaN or infinite")),
    (np.full(SIZE, np.inf), ("frame 0", "NaN or infinite")),
    (np.zeros((*SIZE, 2)), ("frame 0", "depth of shape")),
    (None, ("frame 0", "no depth")),
])
def test_bad_depth_is_refused(tmp_path: Path, depth, parts) -> None:
    w = _writer(tmp_path, arrays=("rgb", "depth", "contact"))
    try:
        with pytest.raises(VtsError) as err:
            w.add_frame(RGB, depth=depth, contact=np.zeros(SIZE, bool))
        _one_line(err, "episode 0", *parts)
    finally:
        w.close()


def test_a_dtype_other_than_the_first_frames_is_refused(tmp_path: Path) -> None:
    w = _writer(tmp_path, arrays=("rgb", "depth", "contact"))
    try:
        w.add_frame(RGB, depth=np.zeros(SIZE, np.float32), contact=np.zeros(SIZE, bool))
        with pytest.raises(VtsError) as err:
            w.add_frame(RGB, depth=np.zeros(SIZE, np.float64), contact=np.zeros(SIZE, bool))
        _one_line(err, "episode 0, frame 1", "float64", "first frame's float32")
    finally:
        w.close()


@pytest.mark.parametrize(("save", "parts"), [
    ({"slip_onset_s": 0.5}, ("episode 0", "slip_onset_s 0.5", "outside the take")),
    ({"slip_onset_s": -0.01}, ("episode 0", "outside the take")),
    ({"slip_onset_s": float("nan")}, ("episode 0", "outside the take")),
    ({"object": ""}, ("episode 0", "object must be a non-empty name")),
    ({"fps": 0}, ("episode 0", "frame rate")),
    ({"calibration_sha256": "xyz"}, ("episode 0", "sha256")),
    ({"frames": [1]}, ("episode 0", "'frames' is taken")),
    ({"force": 1.0}, ("episode 0", "'force' is already a per-frame column")),
])
def test_bad_episode_is_refused_and_its_frames_kept(tmp_path: Path, save, parts) -> None:
    w = _writer(tmp_path)
    try:
        for i in range(3):
            w.add_frame(RGB, timestamp=i / FPS, force=1.0)
        args = {"object": "mug", "session": "s0", **save}
        with pytest.raises(VtsError) as err:
            w.save_episode(**args)
        _one_line(err, *parts)
        assert w.pending == 3 and w.episodes == 0
        assert w.save_episode(object="mug", session="s0", slip_onset_s=0.04) == 0
    finally:
        w.close()


def test_empty_episode_and_empty_dataset_are_refused(tmp_path: Path) -> None:
    w = _writer(tmp_path)
    with pytest.raises(VtsError) as err:
        w.save_episode(object="mug", session="s0")
    _one_line(err, "episode 0", "no frames")
    with pytest.raises(VtsError) as err:
        w.finish()
    _one_line(err, "no episodes saved")
    w.add_frame(RGB)
    with pytest.raises(VtsError) as err:
        w.finish()
    _one_line(err, "1 frame(s) added since the last save_episode")
    assert w.discard_episode() == 1
    w.close()
    assert not (tmp_path / "ds").exists()


def test_add_episode_keeps_nothing_of_a_refused_episode(tmp_path: Path) -> None:
    ep = take(0, 10)
    ep["timestamps"] = list(ep["timestamps"])
    ep["timestamps"][6] = ep["timestamps"][5]
    with _writer(tmp_path) as w:
        with pytest.raises(VtsError) as err:
            w.add_episode(**ep)
        _one_line(err, "episode 0, frame 6", "repeats")
        assert w.pending == 0 and w.episodes == 0
        with pytest.raises(VtsError) as err:
            w.add_episode(ep["frames"], timestamps=[0.0], object="mug", session="s0")
        _one_line(err, "timestamps has 1 values for 10 frames")
        w.add_episode(**take(1, 5))
    assert vtsbench.load(tmp_path / "ds").episodes.index.column("length").to_pylist() == [5]


def test_context_manager_leaves_the_partial_folder_on_an_exception(tmp_path: Path) -> None:
    out = tmp_path / "ds"
    with pytest.raises(RuntimeError, match="camera"), _writer(tmp_path) as w:
        w.add_episode(**take(0, 5))
        raise RuntimeError("camera unplugged")
    assert not out.exists() and w.partial.is_dir()
    assert not list(w.partial.rglob("info.json"))  # nothing looks complete
    with pytest.raises(VtsError, match="resume=True"):
        _writer(tmp_path)
    with _writer(tmp_path, resume=True) as w2:
        assert w2.episodes == 1
    assert len(vtsbench.load(out).episodes) == 1 and not w.partial.exists()


def test_existing_output_overwrite_and_resume_parameters(tmp_path: Path) -> None:
    out = write_takes(tmp_path / "ds", takes()[:1])
    with pytest.raises(VtsError) as err:
        _writer(tmp_path)
    _one_line(err, "already exists", "overwrite=True")
    write_takes(out, takes()[1:2], overwrite=True)
    assert vtsbench.load(out).episodes.index.column("length").to_pylist() == [9]
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    with pytest.raises(VtsError, match="not a vtsbench dataset"):
        vtsbench.create(other, overwrite=True)
    w = vtsbench.create(tmp_path / "p", shard_mb=SHARD_MB)
    w.add_episode(**take(0, 5))
    w.close()
    with pytest.raises(VtsError) as err:
        vtsbench.create(tmp_path / "p", shard_mb=SHARD_MB, arrays=("rgb", "depth", "contact"),
                        resume=True)
    _one_line(err, "resume: arrays")
    with pytest.raises(VtsError, match="depth and contact come together"):
        vtsbench.create(tmp_path / "q", arrays=("rgb", "depth"))


def test_a_second_writer_is_locked_out(tmp_path: Path) -> None:
    w = _writer(tmp_path)
    try:
        with pytest.raises(VtsError, match="lock is held"):
            _writer(tmp_path, resume=True)
    finally:
        w.close()


def test_no_warning_without_gaps(tmp_path: Path) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        write_takes(tmp_path / "ds", takes()[:2])


def test_a_partial_folder_with_nothing_saved_starts_afresh(tmp_path: Path) -> None:
    w = _writer(tmp_path)
    for i in range(12):  # a shard of unsaved frames written, then the writer stops
        w.add_frame(RGB, timestamp=i / FPS)
    w.close()
    with _writer(tmp_path, arrays=("rgb", "depth", "contact")) as w2:  # no resume needed
        assert (w2.episodes, w2.frames) == (0, 0)
        w2.add_episode(**take(0, 5, depth=True))
    assert vtsbench.load(tmp_path / "ds").episodes[0]["rgb"].shape == (5, *SIZE, 3)


def test_a_build_never_takes_over_a_writers_partial_folder(sim_recordings: Path,
                                                           tmp_path: Path) -> None:
    from vtsbench.dataset.build import BuildOptions, build

    w = _writer(tmp_path)
    w.add_episode(**take(0, 5))
    w.close()
    with pytest.raises(VtsError, match="partial dataset of episodes"):
        build(sim_recordings, tmp_path / "ds", BuildOptions(shard_mb=0.15))
    w = _writer(tmp_path, resume=True)
    assert w.episodes == 1
    w.close()
