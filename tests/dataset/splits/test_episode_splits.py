"""Split files over episodes, made by vtsbench.create at finish(): object-held-out and
session-held-out parts of whole episodes, leak-checked, seeded and byte for byte
deterministic; a scheme the episodes cannot support is skipped with its reason."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

import vtsbench
from tests.fixtures.episodes import take, takes, write_takes
from vtsbench.dataset.format.layout import INFO_PATH, split_path
from vtsbench.dataset.format.records import SplitFile, schema_errors
from vtsbench.dataset.splits.episodes import (
    EPISODE,
    episode_leaks,
    make_episode_splits,
    split_table,
)
from vtsbench.dataset.tools.verify import verify


@pytest.fixture(scope="module")
def ds_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Four takes: objects mug, box, cloth, mug; sessions s0, s1, s0, s1."""
    return write_takes(tmp_path_factory.mktemp("eps") / "ds", takes())


def _table(objects: list[str], sessions: list[str]) -> pa.Table:
    return pa.table({"episode_id": [f"episode-{i:06d}" for i in range(len(objects))],
                     "object": objects, "session": sessions})


def test_writer_makes_both_splits_of_episode_ids(ds_path: Path) -> None:
    ds = vtsbench.load(ds_path)
    assert ds.splits == ["unseen_objects", "unseen_sessions"]
    ids = set(ds.episodes.ids)
    info = json.loads((ds_path / INFO_PATH).read_text())
    assert info["build"]["splits_skipped"] == {}
    for name in ds.splits:
        doc = json.loads((ds_path / split_path(name)).read_text())
        assert schema_errors(doc, "split") == []
        assert doc["kind"] == EPISODE
        listed = [i for part in doc["parts"].values() for i in part]
        assert sorted(listed) == sorted(ids)  # every episode once
        assert info["counts"]["splits"][name] == {p: len(v) for p, v in doc["parts"].items()}
    assert verify(ds_path).ok


def test_held_out_objects_never_in_train_windows(ds_path: Path) -> None:
    ds = vtsbench.load(ds_path)
    held = set(ds.split_file("unseen_objects").params["held_out_objects"])
    assert held
    for part, inside in (("train", False), ("test", True)):
        eps = ds.episodes.split("unseen_objects", part)
        wins = eps.windows(length=4, stride=1)
        objects = {ds.episodes[int(p)]["object"] for p in set(wins.episode_index.tolist())}
        assert objects and all((o in held) == inside for o in objects)
    sess = ds.split_file("unseen_sessions")
    train = {ds.episodes.split("unseen_sessions", "train")[i]["session"]
             for i in range(len(ds.episodes.split("unseen_sessions", "train")))}
    test = set(sess.params["sessions"]["test"])
    assert train and not train & test


def test_same_seed_same_bytes(tmp_path: Path, ds_path: Path) -> None:
    again = write_takes(tmp_path / "again", takes())
    for name in ("unseen_objects", "unseen_sessions"):
        assert (again / split_path(name)).read_bytes() == (ds_path / split_path(name)).read_bytes()
    other = write_takes(tmp_path / "seed7", takes(), seed=7)
    assert json.loads((other / split_path("unseen_objects")).read_text())["seed"] == 7


def test_order_of_episodes_does_not_change_the_split() -> None:
    objs = [f"o{i % 5}" for i in range(20)]
    sess = [f"s{i % 4}" for i in range(20)]
    a = make_episode_splits(_table(objs, sess), seed=3)
    perm = np.random.default_rng(0).permutation(20)
    t = _table(objs, sess).take(pa.array(perm))
    b = make_episode_splits(t, seed=3)
    assert [s.to_bytes() for s in a.splits] == [s.to_bytes() for s in b.splits]
    assert {s.name for s in a.splits} == {"unseen_objects", "unseen_sessions"}
    assert len(a.get("unseen_sessions").parts) == 3  # 4 sessions: train, val and test


def test_one_object_skips_unseen_objects_with_reason(tmp_path: Path) -> None:
    out = write_takes(tmp_path / "one", [{**take(k, 8), "object": "mug"} for k in range(3)])
    ds = vtsbench.load(out)
    assert ds.splits == ["unseen_sessions"]
    skipped = json.loads((out / INFO_PATH).read_text())["build"]["splits_skipped"]
    assert "at least 2 objects" in skipped["unseen_objects"]
    assert "'mug'" in skipped["unseen_objects"]


def test_one_session_skips_unseen_sessions_with_reason() -> None:
    rep = make_episode_splits(_table(["a", "b", "c"], ["s0"] * 3))
    assert "one session ('s0')" in rep.skipped["unseen_sessions"]
    assert rep.skipped["unseen_sessions"].startswith("unseen_sessions: every episode")
    assert [s.name for s in rep.splits] == ["unseen_objects"]


def test_leak_check_names_shared_object_and_unknown_id() -> None:
    t = _table(["a", "a", "b"], ["s0", "s1", "s0"])
    bad = SplitFile("unseen_objects", EPISODE, "", 0,
                    {"train": ["episode-000000"], "test": ["episode-000001", "episode-000009"]},
                    ["object:test"], {})
    lines = episode_leaks(bad, split_table(t))
    assert any("'episode-000009'" in x and "not in the dataset" in x for x in lines)
    assert any("object 'a' in both train and test" in x for x in lines)
    good = make_episode_splits(t).get("unseen_objects")
    assert good is not None and episode_leaks(good, split_table(t)) == []


def test_verify_reports_an_episode_split_that_leaks(ds_path: Path, tmp_path: Path) -> None:
    """An episode copied into a second part of unseen_objects in place of another: verify
    names the leak (and the changed file), as it does for the other kinds' splits. (Listing
    more ids than the dataset has episodes is refused before, as the loader refuses it.)"""
    import shutil

    copy = tmp_path / "ds"
    shutil.copytree(ds_path, copy)
    path = copy / split_path("unseen_objects")
    doc = json.loads(path.read_text())
    moved = doc["parts"]["test"][0]
    doc["parts"]["train"] = sorted([*doc["parts"]["train"][1:], moved])
    path.write_text(json.dumps(doc))
    problems = verify(copy).problems
    assert any("leak: unseen_objects" in p and moved in p for p in problems), problems
    assert any("sha256 mismatch" in p for p in problems)
