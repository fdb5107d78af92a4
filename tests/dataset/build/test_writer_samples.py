"""EpisodeWriter.add_sample: the paper's static frames and slip sequences as views of saved
episodes (format 1.3): their indexes, split files and info.json; every refusal one line; the
samples committed with the next save (or finish), kept or lost deterministically by a crash."""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest

import vtsbench
from tests.fixtures.datasets import tree_bytes
from tests.fixtures.episodes import FPS, SHARD_MB, takes
from tests.fixtures.faults import Crash, FailingOs, count_renames, run_killed
from vtsbench import atomic
from vtsbench.dataset.build.staging import partial_path
from vtsbench.dataset.format.records import SplitFile
from vtsbench.errors import VtsError

T = 4


def samples_of(k: int, n: int) -> list[dict[str, Any]]:
    """The samples declared on episode k of n frames: a static frame, then windows of T at
    stride 2 (overlapping) with labels."""
    out: list[dict[str, Any]] = [{"kind": "static", "start": 1, "press_depth_mm": 0.25 * k,
                                  "contact_px": (3.0 + k, 4.0), "mm_per_px": (0.05, 0.05),
                                  "fields": {"take": f"t{k}"}}]
    for s in range(0, n - T + 1, 2):
        slip = s >= 4
        out.append({"kind": "slip", "start": s, "state": "slip" if slip else "press",
                    "direction": (k + s) % 8 if slip else None, "motion_mm": (0.1 * s, -0.2),
                    "mm_per_px": (0.05, 0.05), "sample_id": f"ep{k}-w{s:03d}"})
    return out


def write(out: Path, w: Any = None, **create: Any) -> Path:
    """Four takes, each followed by its samples (resumed: what is saved is skipped)."""
    w = w or vtsbench.create(out, fps=FPS, shard_mb=SHARD_MB, sensor="gelsight-mini",
                             name="views", frames_per_sequence=T, **create)
    try:
        for k, ep in enumerate(takes()):
            if k >= w.episodes:
                w.add_episode(**ep)
            for s in samples_of(k, len(ep["frames"])):
                s = dict(s)
                if s.get("sample_id") in w.sample_ids or (
                        f"episode-{k:06d}-f{s['start']:06d}" in w.sample_ids):
                    continue
                w.add_sample(s.pop("kind"), episode=k, **s)
        return w.finish()
    finally:
        w.close()


@pytest.fixture(scope="module")
def views(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write(tmp_path_factory.mktemp("views") / "ds")


def test_format_13_indexes_and_info(views: Path) -> None:
    info = json.loads((views / "meta/info.json").read_text())
    assert info["format_version"] == "1.3" and info["sample_storage"] == "episodes"
    assert not (views / "data/static.zarr").exists() and not (views / "data/slip.zarr").exists()
    assert set(info["zarr"]["samples_per_shard"]) == {"episodes"}
    assert info["frames_per_sequence"] == T
    eps = takes()
    n_static, n_slip = len(eps), sum(len(range(0, len(e["frames"]) - T + 1, 2)) for e in eps)
    assert info["shapes"]["static"]["rgb"] == [n_static, 24, 32, 3]
    assert info["shapes"]["slip"]["rgb"] == [n_slip, T, 24, 32, 3]
    assert info["counts"]["static"]["samples"] == n_static
    assert info["counts"]["slip"]["samples"] == n_slip
    slip = pq.read_table(views / "index/slip.parquet").to_pylist()
    starts = np.cumsum([0] + [len(e["frames"]) for e in eps])
    objects = sorted({e["object"] for e in eps})
    assert [r["row"] for r in slip] == list(range(n_slip))
    for r in slip:
        k, s = int(r["sample_id"][2]), int(r["sample_id"][-3:])
        assert r["episode_index"] == k and r["frame_row"] == starts[k] + s
        assert r["object"] == eps[k]["object"] and r["session"] == eps[k]["session"]
        assert r["class_idx"] == objects.index(eps[k]["object"])
        assert r["source"] == f"episode-{k:06d}[{s}:{s + T}]"
        assert r["state"] == ("slip" if s >= 4 else "press")
        assert r["motion_dx_mm"] == pytest.approx(0.1 * s)
    static = pq.read_table(views / "index/static.parquet").to_pylist()
    assert [r["sample_id"] for r in static] == [f"episode-{k:06d}-f000001" for k in range(4)]
    assert [r["take"] for r in static] == ["t0", "t1", "t2", "t3"]
    assert [r["frame_row"] for r in static] == [int(s) + 1 for s in starts[:4]]
    # the sample splits under their names, the episodes' beside them
    names = set(info["splits"])
    assert {"episode_unseen_objects", "episode_unseen_sessions"} <= names
    assert "object_folds" in names and "seen" in names
    for name in names:
        doc = json.loads((views / "meta/splits" / f"{name}.json").read_text())
        assert doc["kind"] == ("episode" if name.startswith("episode_") else doc["kind"])


def test_samples_read_the_episodes_frames(views: Path) -> None:
    from vtsbench.dataset.tools.verify import verify

    ds = vtsbench.load(views)
    eps = takes()
    for i in range(len(ds.slip)):
        x = ds.slip[i]
        k, s = int(x["sample_id"][2]), int(x["sample_id"][-3:])
        assert np.array_equal(x["rgb"], eps[k]["frames"][s:s + T])
    for i in range(len(ds.static)):
        assert np.array_equal(ds.static[i]["rgb"], eps[i]["frames"][1])
    assert verify(views).ok


def test_same_calls_same_bytes(views: Path, tmp_path: Path) -> None:
    assert tree_bytes(write(tmp_path / "ds")) == tree_bytes(views)


@pytest.mark.parametrize(("call", "parts"), [
    (dict(kind="tile", episode=0, start=0), ["kind 'tile'"]),
    (dict(kind="slip", episode=7, start=0), ["episode 7", "not a saved episode"]),
    (dict(kind="slip", episode="nope", start=0), ["'nope'", "not a saved episode"]),
    (dict(kind="slip", episode=0, start=11), ["frames [11, 15)", "outside", "13 frames"]),
    (dict(kind="slip", episode=0, start=-1), ["outside"]),
    (dict(kind="slip", episode=0, start=1.5), ["start must be a frame number"]),
    (dict(kind="slip", episode=0, start=0, sample_id="a"), ["'a'", "already taken"]),
    (dict(kind="static", episode=0, start=0, sample_id="a"), ["'a'", "already taken"]),
    (dict(kind="slip", episode=0, start=0, colour="red"), ["unknown label 'colour'"]),
    (dict(kind="static", episode=0, start=0, state="slip"), ["state is a label of slip"]),
    (dict(kind="slip", episode=0, start=0, state="press", direction=2), ["direction (2)",
                                                                          "press, not slip"]),
    (dict(kind="slip", episode=0, start=0, state="slipping"), ["state 'slipping'"]),
    (dict(kind="slip", episode=0, start=0, motion_mm=(1.0, float("nan"))), ["motion_mm"]),
    (dict(kind="slip", episode=0, start=0, mm_per_px=(0.0, 0.1)), ["mm_per_px", "positive"]),
    (dict(kind="slip", episode=0, start=0, fields={"Bad Name": "x"}), ["fields", "Bad Name"]),
    (dict(kind="slip", episode=0, start=0, fields={"row": "x"}), ["fields", "'row'"]),
])
def test_refusals_are_one_line(tmp_path: Path, call: dict[str, Any], parts: list[str]) -> None:
    w = vtsbench.create(tmp_path / "ds", fps=FPS, shard_mb=SHARD_MB, frames_per_sequence=T)
    try:
        w.add_episode(**takes()[0])
        w.add_sample("slip", episode=0, start=0, sample_id="a")
        with pytest.raises(VtsError) as e:
            kind = call.pop("kind")
            w.add_sample(kind, **call)
        msg = str(e.value)
        assert "\n" not in msg and all(p in msg for p in parts), msg
        assert w.samples == 1  # nothing of a refused sample kept
    finally:
        w.close()


def test_frames_per_sequence_is_checked(tmp_path: Path) -> None:
    with pytest.raises(VtsError, match=r"frames_per_sequence must be 1\.\.1000"):
        vtsbench.create(tmp_path / "ds", frames_per_sequence=0)


def test_a_split_whose_parts_share_frames_is_refused_and_a_scheme_skipped(tmp_path: Path
                                                                        ) -> None:
    w = vtsbench.create(tmp_path / "ds", fps=FPS, shard_mb=SHARD_MB, frames_per_sequence=T)
    try:
        for ep in takes():
            w.add_episode(**ep)
        for k, ep in enumerate(takes()):  # windows at stride 1: every frame in several
            for s in range(len(ep["frames"]) - T + 1):
                w.add_sample("slip", episode=k, start=s, state="slip", direction=1)
        w.add_split(SplitFile("mine", "slip", "overlapping windows in train and test", 0,
                              {"train": ["episode-000002-s000000"],
                               "test": ["episode-000002-s000001"]}, []))
        with pytest.raises(VtsError) as e:
            w.finish()
        msg = str(e.value)
        assert "\n" not in msg and "split mine leaks" in msg and "share frame row" in msg, msg
        assert not (tmp_path / "ds").exists()
        n = w.samples
    finally:
        w.close()
    # the samples were committed before the refusal: a resumed writer finishes without it
    w = vtsbench.create(tmp_path / "ds", fps=FPS, shard_mb=SHARD_MB, frames_per_sequence=T,
                        resume=True)
    try:
        assert w.samples == n
        w.finish()
    finally:
        w.close()
    info = json.loads((tmp_path / "ds/meta/info.json").read_text())
    skipped = info["build"]["splits_skipped"]
    # unseen_objects draws val as whole takes: overlapping windows never straddle train and val
    assert "unseen_objects" not in skipped and "unseen_objects" in info["splits"], skipped
    assert "object_folds" in info["splits"]
    split = json.loads((tmp_path / "ds/meta/splits/unseen_objects.json").read_text())
    take = {p: {i.rsplit("-s", 1)[0] for i in split["parts"][p]} for p in split["parts"]}
    assert take["val"] and not take["train"] & take["val"]
    from vtsbench.dataset.tools.verify import verify

    assert verify(tmp_path / "ds").ok


def test_a_failure_at_every_write_and_rename_then_resume(views: Path, tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch
                                                         ) -> None:
    steps = count_renames(monkeypatch, lambda: write(tmp_path / "count" / "ds"))
    assert steps > 20
    for at in range(1, steps + 1):
        out = tmp_path / f"run{at}" / "ds"
        monkeypatch.setattr(atomic, "os", FailingOs(at))
        try:
            write(out)
            raise AssertionError(f"no failure at step {at}")
        except Crash:
            pass
        finally:
            monkeypatch.setattr(atomic, "os", os)
        assert not out.exists(), f"step {at}: OUT exists after a failed write"
        w = vtsbench.create(out, fps=FPS, shard_mb=SHARD_MB, sensor="gelsight-mini",
                            name="views", frames_per_sequence=T, resume=True)
        assert tree_bytes(write(out, w)) == tree_bytes(views), f"step {at}: other bytes"
        assert not partial_path(out).exists()


def test_sigkill_after_add_sample_loses_the_samples_since_the_last_save(views: Path,
                                                                       tmp_path: Path) -> None:
    if not hasattr(signal, "SIGKILL"):
        pytest.skip("needs SIGKILL")
    out = tmp_path / "ds"
    run_killed(f"""
        import vtsbench
        from tests.fixtures.episodes import FPS, SHARD_MB, takes
        eps = takes()
        w = vtsbench.create({str(out)!r}, fps=FPS, shard_mb=SHARD_MB, sensor="gelsight-mini",
                            name="views", frames_per_sequence={T})
        w.add_episode(**eps[0])
        w.add_sample("static", episode=0, start=1, sample_id="kept")
        w.add_episode(**eps[1])  # commits "kept"
        w.add_sample("static", episode=1, start=1, sample_id="lost")
    """)
    w = vtsbench.create(out, fps=FPS, shard_mb=SHARD_MB, sensor="gelsight-mini", name="views",
                        frames_per_sequence=T, resume=True)
    try:
        assert (w.episodes, w.samples, w.sample_ids) == (2, 1, frozenset({"kept"}))
    finally:
        w.close()
