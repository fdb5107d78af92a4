"""The pieces of episodes-first storage together, end to end: format 1.3 samples as views of
episodes whose RGB is stored as video (ffv1 bit for bit against a Zarr-stored twin, h264 as
the codec decodes it), verify on them (no chunk of the video-held `rgb` array to decode), the
card and `vtsbench info` saying how the frames are stored, `vtsbench export-hf` of a video
dataset, `vtsbench build --store episodes --video`, and a video dataset read over http."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import vtsbench
from tests.fixtures.cli import clean, run
from tests.fixtures.episode_video import video_takes, write_video_takes
from tests.fixtures.serve import serve
from tests.fixtures.views import SLIP, STATIC, T, write_views
from vtsbench.cli import app
from vtsbench.dataset.build import BuildOptions
from vtsbench.dataset.build.options import check_options
from vtsbench.dataset.format.layout import VIDEOS_DIR, episode_video_path
from vtsbench.dataset.format.video import CODECS
from vtsbench.dataset.read.video import decode_frames
from vtsbench.dataset.tools.hub_layout import episode_file
from vtsbench.dataset.tools.verify import verify
from vtsbench.errors import VtsError

ARRAYS = ("rgb", "depth", "contact")


@pytest.fixture(scope="module")
def video_views(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The views dataset of tests/fixtures/views.py with its RGB as ffv1 and as h264."""
    root = tmp_path_factory.mktemp("video-views")
    return {c: write_views(root / c, video=c) for c in ("ffv1", "h264")}


def all_samples(ds: vtsbench.VtsDataset, kind: str) -> list[dict]:
    view = getattr(ds, kind)
    return [view[i] for i in range(len(view))]


def test_ffv1_views_read_bit_for_bit_as_the_zarr_twin(video_views: dict[str, Path],
                                                     views_dataset: Path) -> None:
    z, v = vtsbench.load(views_dataset), vtsbench.load(video_views["ffv1"])
    assert v.info.views and v.info.format_version == "1.3"
    assert v.info.episodes is not None and v.info.episodes.video == CODECS["ffv1"]
    assert z.info.episodes is not None and z.info.episodes.video is None
    assert not (video_views["ffv1"] / "data" / "slip.zarr").exists()
    assert not (video_views["ffv1"] / "data" / "episodes.zarr" / "rgb" / "c").exists()
    for kind, n in (("slip", len(SLIP)), ("static", len(STATIC))):
        a, b = all_samples(z, kind), all_samples(v, kind)
        assert len(a) == len(b) == n
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert x["sample_id"] == y["sample_id"]
            for name in ARRAYS:
                assert x[name].dtype == y[name].dtype and np.array_equal(x[name], y[name]), \
                    (kind, i, name)
        rows = list(range(n))[::-1]  # one batched read, out of order
        got, want = getattr(v, kind).read(rows, ARRAYS), getattr(z, kind).read(rows, ARRAYS)
        for name in ARRAYS:
            assert np.array_equal(got[name], want[name]), (kind, name)
    report = verify(video_views["ffv1"])
    assert report.ok, report.problems


def test_h264_views_are_what_the_codec_decodes(video_views: dict[str, Path],
                                               views_dataset: Path) -> None:
    root = video_views["h264"]
    v, z = vtsbench.load(root), vtsbench.load(views_dataset)
    lengths = v.episodes.index.column("length").to_pylist()
    for i, (ep, start, _) in enumerate(SLIP):
        path = root / episode_video_path(ep, CODECS["h264"].suffix)
        s = v.slip[i]
        assert np.array_equal(s["rgb"], decode_frames(path, start, T,
                                                      expected_frames=lengths[ep])), i
        assert np.array_equal(s["depth"], z.slip[i]["depth"])  # lossless, in Zarr
    for i, (ep, frame) in enumerate(STATIC):
        path = root / episode_video_path(ep, CODECS["h264"].suffix)
        assert np.array_equal(v.static[i]["rgb"], decode_frames(path, frame, 1)[0]), i
    lossy = v.slip[1]["rgb"].astype(int) - z.slip[1]["rgb"].astype(int)
    assert np.abs(lossy).max() > 0  # lossy: not the frames written, but what h264 gives back
    report = verify(root)
    assert report.ok, report.problems


def test_verify_decodes_every_chunk_but_the_video_held_rgb(video_views: dict[str, Path],
                                                           views_dataset: Path,
                                                           tmp_path: Path) -> None:
    zarr_shards = verify(views_dataset).shards
    assert verify(video_views["ffv1"]).shards * 3 == zarr_shards * 2  # depth, contact only
    out = Path(shutil.copytree(video_views["ffv1"], tmp_path / "ds"))
    shard = next(p for p in sorted((out / "data" / "episodes.zarr" / "depth").rglob("*"))
                 if p.is_file() and p.name != "zarr.json")
    shard.unlink()
    problems = verify(out).problems
    assert any("episodes.zarr/depth" in p and "is missing" in p for p in problems), problems
    assert not any("episodes.zarr/rgb" in p for p in problems), problems


def test_card_and_info_say_how_the_frames_are_stored(video_views: dict[str, Path],
                                                     views_dataset: Path) -> None:
    def card(root: Path) -> str:
        return " ".join((root / "README.md").read_text().split())

    h264 = card(video_views["h264"])
    assert "stored as video" in h264 and "data/videos/episode-000000.mp4" in h264
    assert "libx264" in h264 and "crf 18" in h264 and "lossy" in h264
    assert "are views of those frames" in h264
    assert "lossless: decoding gives the frames back bit for bit" in card(video_views["ffv1"])
    assert "stored as video" not in card(views_dataset)
    assert "`data/episodes.zarr` is a Zarr v3 group with `rgb`" in card(views_dataset)
    for root, words in ((video_views["ffv1"], ["RGB as video", "ffv1", "lossless",
                                               "depth and contact in Zarr v3", "views",
                                               f"{VIDEOS_DIR}"]),
                        (views_dataset, ["frames stored as Zarr v3 (zstd level 3", "views"])):
        res = CliRunner().invoke(app, ["info", str(root)], terminal_width=200)
        assert res.exit_code == 0, res.output
        text = " ".join(res.output.split())
        assert all(w in text for w in words), (words, text[:1500])


def test_export_hf_of_video_episodes_holds_the_decoded_frames(tmp_path: Path,
                                                             monkeypatch: pytest.MonkeyPatch
                                                             ) -> None:
    import datasets
    import huggingface_hub.constants

    monkeypatch.setattr(datasets.config, "HF_HUB_OFFLINE", True)
    monkeypatch.setattr(huggingface_hub.constants, "HF_HUB_OFFLINE", True)
    root = write_video_takes(tmp_path / "ds", video_takes(depth=True), "h264")
    res = run("export-hf", root, "--quiet")
    assert res.exit_code == 0, res.output
    ds = vtsbench.load(root)
    files = [str(root / episode_file(e)) for e in range(len(ds.episodes))]
    rows = datasets.load_dataset("parquet", data_files=files, split="train",
                                 cache_dir=str(tmp_path / "cache")).with_format("numpy")
    scale = np.float32(ds.info.depth_scale_mm)
    start = 0
    for e in range(len(ds.episodes)):
        want = ds.episodes[e]
        got = rows[start:start + len(want["timestamps"])]
        start += len(want["timestamps"])
        assert np.array_equal(np.stack(got["observation.images.rgb"]), want["rgb"]), e
        mm = np.stack(got["observation.images.depth"]).view(np.int16).astype(np.float32) * scale
        assert np.array_equal(mm[..., 0] if mm.ndim == 4 else mm, want["depth"]), e
    assert start == len(rows)
    report = verify(root)
    assert report.ok, report.problems


def test_build_store_episodes_with_video(make_recordings, tmp_path: Path) -> None:
    root, _ = make_recordings()
    outs = {}
    for video in (None, "ffv1", "h264"):
        out = tmp_path / f"ds-{video}"
        res = run("build", root, out, "--no-depth", "--store", "episodes", "--quiet",
                  *(("--video", video) if video else ()))
        assert res.exit_code == 0, res.output
        outs[video] = out
    z, f, h = (vtsbench.load(outs[k]) for k in (None, "ffv1", "h264"))
    assert f.info.episodes is not None and f.info.episodes.video == CODECS["ffv1"]
    assert h.info.episodes is not None and h.info.episodes.video == CODECS["h264"]
    assert sorted(p.name for p in (outs["ffv1"] / VIDEOS_DIR).iterdir()) == [
        f"episode-{k:06d}.mkv" for k in range(len(z.episodes))]
    for kind in ("static", "slip"):
        assert len(getattr(z, kind)) > 0
        for x, y in zip(all_samples(z, kind), all_samples(f, kind), strict=True):
            assert x["sample_id"] == y["sample_id"] and np.array_equal(x["rgb"], y["rgb"])
    for k in range(len(h.episodes)):  # h264: the episodes are what the codec decodes
        length = int(h.episodes.index.column("length")[k].as_py())
        path = outs["h264"] / episode_video_path(k, CODECS["h264"].suffix)
        assert np.array_equal(h.episodes[k]["rgb"], decode_frames(path, 0, length))
    for out in outs.values():
        assert verify(out).ok
    res = run("build", root, tmp_path / "again", "--no-depth", "--store", "episodes", "--quiet",
              "--video", "ffv1")
    assert res.exit_code == 0, res.output
    assert (tmp_path / "again" / "meta" / "info.json").read_bytes() != b""
    same = json.loads((tmp_path / "again" / "meta" / "info.json").read_text())
    assert same["dataset_sha256"] == f.info.dataset_sha256  # the same bytes each time


def test_video_without_store_episodes_is_one_line(make_recordings, tmp_path: Path) -> None:
    root, _ = make_recordings()
    clean(run("build", root, tmp_path / "ds", "--no-depth", "--video", "ffv1", "--quiet"), 2,
          "--video", "--store episodes")
    assert not (tmp_path / "ds").exists()
    clean(run("build", root, tmp_path / "ds", "--no-depth", "--store", "episodes", "--video",
              "mpeg4"), 2, "--video")
    with pytest.raises(VtsError, match="--video must be one of ffv1, h264, av1"):
        check_options(BuildOptions(store="episodes", video="h264-crf28"))


def test_a_video_dataset_over_http_reads_windows_and_samples(video_views: dict[str, Path]
                                                             ) -> None:
    local = vtsbench.load(video_views["h264"])
    with serve(video_views["h264"].parent) as base:
        remote = vtsbench.load(f"{base}/h264")
        for length, stride in ((8, 8), (5, 2)):
            a = local.episodes.windows(length=length, stride=stride)
            b = remote.episodes.windows(length=length, stride=stride)
            assert len(a) == len(b) > 0
            got, want = b.read(range(len(b)), ARRAYS), a.read(range(len(a)), ARRAYS)
            for name in ARRAYS:
                assert np.array_equal(got[name], want[name]), (length, stride, name)
        ts = remote.episodes.windows(delta_timestamps=[-0.08, -0.04, 0.0], pad="edge")
        assert np.array_equal(ts[5]["rgb"], local.episodes.windows(
            delta_timestamps=[-0.08, -0.04, 0.0], pad="edge")[5]["rgb"])
        for i in range(len(SLIP)):
            assert np.array_equal(remote.slip[i]["rgb"], local.slip[i]["rgb"]), i
