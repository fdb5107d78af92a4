"""`vtsbench export-hf` of datasets with episodes: hf/episodes/ laid out as LeRobot v2.1 lays out
a dataset (meta files, one parquet file per episode), a row per frame equal to `ds.episodes`
bit for bit, read by `datasets` offline (parquet files, the card's configs, streaming); resumed
after a failure; a dataset without episodes gets none."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

import vtsbench
from vtsbench.cli import app
from vtsbench.dataset.tools.hub_layout import EPISODES_HUB, episode_file
from vtsbench.dataset.tools.verify import verify
from vtsbench.labels import DIRECTION_NAMES, STATES

SIZE = (48, 64)
FPS = 30.0


def take(k: int, n: int, depth: bool) -> dict[str, Any]:
    """Episode k of n frames of 48x64 with labels, extra values and uneven timestamps."""
    rng = np.random.default_rng(10 + k)
    ep: dict[str, Any] = {
        "frames": rng.integers(0, 256, (n, *SIZE, 3), dtype=np.uint8),
        "timestamps": np.cumsum(rng.uniform(0.8, 1.2, n)) / FPS - 1 / FPS * 0.8,
        "states": [None, "static"] + ["press"] * 2 + ["slip"] * (n - 4),
        "directions": [None] * 4 + [int(d) for d in rng.integers(0, 8, n - 4)],
        "extra": {"force_n": [float(x) for x in rng.normal(size=n)],
                  "marker": [f"m{i % 3}" if i % 4 else None for i in range(n)]},
        "object": ["mug", "box", "cloth"][k % 3], "session": f"s{k % 2}",
        "slip_onset_s": 0.1 if k % 2 else None, "trial": k}
    ep["timestamps"][0] = 0.0
    if depth:
        ep["depth"] = np.round(rng.uniform(-0.5, 2.0, (n, *SIZE)), 3).astype(np.float32)
        ep["contact"] = rng.random((n, *SIZE)) > 0.7
    return ep


def write(out: Path, depth: bool = True, lengths: tuple[int, ...] = (13, 9, 20, 6)) -> Path:
    arrays = ("rgb", "depth", "contact") if depth else ("rgb",)
    with vtsbench.create(out, fps=FPS, arrays=arrays, sensor="gelsight-mini",
                         shard_mb=0.1, name="takes") as w:
        for k, n in enumerate(lengths):
            w.add_episode(**take(k, n, depth))
    return out


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Four episodes (rgb, depth, contact) exported through the command (read-only)."""
    root = write(tmp_path_factory.mktemp("hub-episodes") / "ds")
    res = CliRunner().invoke(app, ["export-hf", str(root), "--workers", "2", "--quiet"])
    assert res.exit_code == 0, res.output
    return root


@pytest.fixture
def offline(monkeypatch: pytest.MonkeyPatch) -> None:
    import datasets
    import huggingface_hub.constants

    monkeypatch.setattr(datasets.config, "HF_HUB_OFFLINE", True)
    monkeypatch.setattr(huggingface_hub.constants, "HF_HUB_OFFLINE", True)


def meta(root: Path, name: str) -> Any:
    path = root / EPISODES_HUB / "meta" / name
    if name.endswith(".jsonl"):
        return [json.loads(line) for line in path.read_text().splitlines()]
    return json.loads(path.read_text())


def check_rows(rows: list[dict[str, Any]], ds: vtsbench.VtsDataset) -> None:
    """Rows read by datasets (numpy format) against ds.episodes: every value bit for bit."""
    scale = np.float32(ds.info.depth_scale_mm)
    tasks = sorted(set(ds.episodes.index.column("object").to_pylist()))
    starts = ds.episodes.index.column("frame_start").to_pylist()
    by_episode: dict[int, list[dict[str, Any]]] = {}
    for r in rows:
        by_episode.setdefault(int(r["episode_index"]), []).append(r)
    for e, got in by_episode.items():
        want = ds.episodes[e]
        assert [int(r["frame_index"]) for r in got] == list(range(len(want["timestamps"])))
        assert np.array_equal([r["timestamp"] for r in got], want["timestamps"])
        assert [int(r["index"]) for r in got] == [starts[e] + i for i in range(len(got))]
        assert {int(r["task_index"]) for r in got} == {tasks.index(want["object"])}
        assert np.array_equal([r["state"] for r in got], want["state"])
        assert np.array_equal([r["direction"] for r in got], want["direction"])
        assert np.array_equal([r["force_n"] for r in got], want["force_n"])
        assert [r["marker"] for r in got] == list(want["marker"])
        rgb = np.stack([r["observation.images.rgb"] for r in got])
        assert rgb.dtype == np.uint8 and np.array_equal(rgb, want["rgb"])
        if "depth" in want:
            counts = np.stack([r["observation.images.depth"] for r in got])
            assert counts.dtype == np.uint16
            mm = counts.view(np.int16).astype(np.float32) * scale
            assert np.array_equal(mm, want["depth"]) and (want["depth"] < 0).any()
            contact = np.stack([r["observation.images.contact"] for r in got])
            assert contact.dtype == bool and np.array_equal(contact, want["contact"])


def test_tree_and_meta_files(exported: Path) -> None:
    ds = vtsbench.load(exported)
    index = ds.episodes.index.to_pylist()
    hub = exported / EPISODES_HUB
    files = sorted(p.relative_to(exported).as_posix() for p in (hub / "data").rglob("*"))
    assert files == ["hf/episodes/data/chunk-000", *[episode_file(e) for e in range(4)]]
    info = meta(exported, "info.json")
    assert info["layout_of"] == "lerobot v2.1 meta files" and "codebase_version" not in info
    assert info["total_episodes"] == 4 and info["total_frames"] == 48 == sum(
        r["length"] for r in index)
    assert info["total_tasks"] == 3 and info["chunks_size"] == 1000 and info["total_chunks"] == 1
    assert info["fps"] == FPS and info["splits"] == {"full": "0:4"}
    assert info["data_path"].format(episode_chunk=0, episode_index=2) == \
        episode_file(2).removeprefix(f"{EPISODES_HUB}/")
    feats = info["features"]
    assert feats["observation.images.rgb"] == {
        "dtype": "image", "shape": [48, 64, 3], "names": ["height", "width", "channel"],
        "info": feats["observation.images.rgb"]["info"]}
    assert feats["observation.images.depth"]["shape"] == [48, 64, 1]
    assert feats["state"]["names"] == list(STATES)
    assert feats["direction"]["names"] == list(DIRECTION_NAMES)
    assert feats["timestamp"]["dtype"] == "float64" and feats["marker"]["dtype"] == "string"
    import pyarrow.parquet as pq

    schema = pq.read_schema(exported / episode_file(0))
    assert list(feats) == schema.names  # every column described, in order
    own = info["vtsbench"]
    want_splits = {name: {("validation" if p == "val" else p): sorted(
        ds.episodes.ids.index(i) for i in ids) for p, ids in ds.split_file(name).parts.items()}
        for name in ds.splits}
    assert own["splits"] == want_splits and own["depth_scale_mm"] == 0.001
    episodes = meta(exported, "episodes.jsonl")
    assert [(e["episode_index"], e["length"], e["tasks"]) for e in episodes] == [
        (r["episode_index"], r["length"], [r["object"]]) for r in index]
    assert [e["vtsbench"]["slip_onset_s"] for e in episodes] == [None, 0.1, None, 0.1]
    assert episodes[1]["vtsbench"]["session"] == "s1" and episodes[0]["vtsbench"]["trial"] == "0"
    assert meta(exported, "tasks.jsonl") == [{"task_index": 0, "task": "box"},
                                             {"task_index": 1, "task": "cloth"},
                                             {"task_index": 2, "task": "mug"}]
    stats = meta(exported, "episodes_stats.jsonl")
    assert [s["stats"]["timestamp"]["count"] for s in stats] == [[r["length"]] for r in index]
    rgb = ds.episodes[2]["rgb"].reshape(-1, 3) / 255.0
    assert np.allclose(np.ravel(stats[2]["stats"]["observation.images.rgb"]["mean"]),
                       rgb.mean(0))
    assert np.allclose(np.ravel(stats[2]["stats"]["observation.images.rgb"]["std"]), rgb.std(0))
    report = verify(exported)
    assert report.ok, report.problems
    assert all(f in ds.info.files for f in (*files[1:], f"{EPISODES_HUB}/meta/info.json"))


def test_parquet_files_load_bit_for_bit(exported: Path, tmp_path: Path, offline: None) -> None:
    import datasets

    ds = vtsbench.load(exported)
    files = [str(exported / episode_file(e)) for e in range(len(ds.episodes))]
    d = datasets.load_dataset("parquet", data_files=files, split="train",
                              cache_dir=str(tmp_path))
    assert d.num_rows == 48
    check_rows(list(d.with_format("numpy")), ds)
    pil = d[0]["observation.images.rgb"]
    assert pil.format == "TIFF" and pil.mode == "RGB"


def test_card_configs_and_streaming(exported: Path, tmp_path: Path, offline: None) -> None:
    import datasets

    ds = vtsbench.load(exported)
    head = yaml.safe_load((exported / "README.md").read_text().split("---\n")[1])
    configs = {c["config_name"]: c for c in head["configs"]}
    assert configs["episodes"].get("default") is True
    assert {"episodes_unseen_objects", "episodes_index", "frames"} <= set(configs)
    d = datasets.load_dataset(str(exported), "episodes", split="full", cache_dir=str(tmp_path))
    rows = list(d.with_format("numpy"))
    assert [int(r["index"]) for r in rows] == list(range(48))
    check_rows(rows, ds)
    stream = datasets.load_dataset(str(exported), "episodes", split="full", streaming=True)
    streamed = list(stream.with_format("numpy"))
    assert [int(r["index"]) for r in streamed] == list(range(48))
    check_rows(streamed, ds)
    test = datasets.load_dataset(str(exported), "episodes_unseen_objects", split="test",
                                 cache_dir=str(tmp_path))
    held = sorted(ds.episodes.ids.index(i) for i in ds.split_file("unseen_objects").parts["test"])
    assert sorted(set(test["episode_index"])) == held
    index = datasets.load_dataset(str(exported), "episodes_index", split="index",
                                  cache_dir=str(tmp_path))
    assert index["episode_id"] == ds.episodes.ids


def test_rgb_only_and_resume(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                             offline: None) -> None:
    """An RGB-only dataset of episodes; an export that fails at its third episode keeps the
    two written and, rerun, gives the files of an export made in one go."""
    import datasets

    from vtsbench.dataset.tools import hub_episodes
    from vtsbench.dataset.tools.hub import export_hf

    once = write(tmp_path / "once", depth=False)
    export_hf(once)
    root = write(tmp_path / "ds", depth=False)
    real, calls = hub_episodes._write_file, []

    def failing(*args: Any) -> None:
        calls.append(args[0])
        if len(calls) == 3:
            raise OSError(28, "No space left on device")
        real(*args)

    monkeypatch.setattr(hub_episodes, "_write_file", failing)
    res = CliRunner().invoke(app, ["export-hf", str(root), "--quiet"])
    assert res.exit_code == 2 and len(res.output.strip().splitlines()) == 1, res.output
    assert "episode_000002.parquet" in res.output and "kept for a rerun" in res.output
    assert not (root / EPISODES_HUB).exists() and verify(root).ok  # the dataset as it was
    monkeypatch.setattr(hub_episodes, "_write_file", real)
    result = export_hf(root)
    assert result.kept == 2 and "2 kept from an interrupted export" in result.summary()
    for rel in [episode_file(e) for e in range(4)] + [
            f"{EPISODES_HUB}/meta/{n}" for n in ("info.json", "episodes.jsonl",
                                                 "tasks.jsonl", "episodes_stats.jsonl")]:
        assert (root / rel).read_bytes() == (once / rel).read_bytes(), rel
    d = datasets.load_dataset(str(root), "episodes", split="full", cache_dir=str(tmp_path / "c"))
    assert "observation.images.depth" not in d.column_names
    assert "depth" not in meta(root, "info.json")["vtsbench"]["arrays"]
    check_rows(list(d.with_format("numpy")), vtsbench.load(root))
    assert verify(root).ok


def test_samples_and_episodes_export_both(tmp_path: Path, offline: None) -> None:
    """A dataset whose samples are views of its episodes: both copies, both configs."""
    import datasets

    from vtsbench.dataset.tools.hub import export_hf

    root = tmp_path / "ds"
    with vtsbench.create(root, fps=FPS, arrays=("rgb",), sensor="gs", shard_mb=0.1,
                         frames_per_sequence=4) as w:
        if not hasattr(w, "add_sample"):
            pytest.skip("this writer cannot declare samples")
        for k, n in enumerate((13, 9, 20, 6)):
            w.add_episode(**take(k, n, False))
        for e in range(4):
            w.add_sample("slip", episode=e, start=1, state="press")
            w.add_sample("static", episode=e, start=0)
    summary = export_hf(root).summary()
    assert "8 samples" in summary and "4 episodes (48 frames)" in summary
    ds = vtsbench.load(root)
    cache = str(tmp_path / "cache")
    slip = datasets.load_dataset(str(root), "slip_all", split="full", cache_dir=cache)
    assert sorted(slip["sample_id"]) == sorted(ds.slip.ids)
    frames = datasets.load_dataset(str(root), "episodes", split="full", cache_dir=cache)
    check_rows(list(frames.with_format("numpy")), ds)
    assert verify(root).ok


def test_bad_input_is_one_line(tmp_path: Path) -> None:
    root = write(tmp_path / "ds", depth=False, lengths=(5, 6))
    frames = root / "index/frames.parquet"
    frames.write_bytes(frames.read_bytes()[:-20])
    res = CliRunner().invoke(app, ["export-hf", str(root)])
    assert res.exit_code == 2 and len(res.output.strip().splitlines()) == 1, res.output
    assert "frames.parquet" in res.output and not (root / EPISODES_HUB).exists()


def test_push_lists_the_episode_files(exported: Path, tmp_path: Path) -> None:
    copy = Path(shutil.copytree(exported, tmp_path / "ds"))
    res = CliRunner().invoke(app, ["push", str(copy), "me/tactile", "--dry-run"],
                             terminal_width=200)
    assert res.exit_code == 0, res.output
    for rel in ("hf/episodes/meta/info.json", "hf/episodes/meta/episodes.jsonl",
                "hf/episodes/meta/tasks.jsonl", "hf/episodes/meta/episodes_stats.jsonl",
                episode_file(0), episode_file(3)):
        assert rel in res.output


def test_no_episodes_no_subtree(vts_dataset: Path, tmp_path: Path) -> None:
    """A dataset without episodes: no hf/episodes/, no episodes config (and an old subtree,
    say from a dataset rebuilt since, is removed)."""
    from vtsbench.dataset.tools.hub import export_hf

    root = Path(shutil.copytree(vts_dataset, tmp_path / "ds"))
    (root / EPISODES_HUB / "meta").mkdir(parents=True)
    (root / EPISODES_HUB / "meta" / "info.json").write_text("{}")
    export_hf(root)
    assert not (root / EPISODES_HUB).exists()
    assert "episodes" not in (root / "README.md").read_text().split("---\n")[1]
