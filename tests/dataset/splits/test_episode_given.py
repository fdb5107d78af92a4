"""A lab's splits over episodes: `vtsbench.create(..., holdout_objects=[...])` makes the scheme
given_objects over whole episodes at finish (the samples' rule: test exactly the listed
objects, val whole objects drawn seeded from the rest), and with samples both splits, holding
out the same objects; `add_split` takes splits of episode ids, leak-checked; the loader,
verify and `vtsbench info` read them as every split."""

from __future__ import annotations

import json
from pathlib import Path

import pyarrow as pa
import pytest

import vtsbench
from tests.fixtures.cli import run
from tests.fixtures.episodes import FPS, SHARD_MB, takes, write_takes
from vtsbench.dataset.format.layout import INFO_PATH, split_path
from vtsbench.dataset.format.records import SampleMeta, SplitFile, schema_errors
from vtsbench.dataset.splits.episodes import EPISODE, given_objects_episodes
from vtsbench.dataset.splits.given import check_given, given_objects_split
from vtsbench.dataset.tools.verify import verify
from vtsbench.errors import VtsError

T = 4  # frames of a slip sample in the datasets with samples


@pytest.fixture(scope="module")
def ds_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Four takes (objects mug, box, cloth, mug), mug held out."""
    return write_takes(tmp_path_factory.mktemp("given") / "ds", takes(), holdout_objects=["mug"])


def _write_with_samples(out: Path, **create: object) -> vtsbench.EpisodeWriter:
    """A writer holding the four takes and a slip sample at frame 2 of each (not finished)."""
    w = vtsbench.create(out, fps=FPS, shard_mb=SHARD_MB, frames_per_sequence=T, **create)
    for ep in takes():
        k = w.add_episode(**ep)
        w.add_sample("slip", episode=k, start=2, state="slip", direction=1)
    return w


def test_given_objects_over_episodes(ds_path: Path) -> None:
    ds = vtsbench.load(ds_path)
    assert ds.splits == ["given_objects", "unseen_objects", "unseen_sessions"]
    doc = json.loads((ds_path / split_path("given_objects")).read_text())
    assert schema_errors(doc, "split") == []
    assert doc["kind"] == EPISODE and doc["disjoint"] == ["object"]
    assert doc["parts"] == {"test": ["episode-000000", "episode-000003"],
                            "train": ["episode-000001", "episode-000002"]}
    assert doc["params"]["held_out_objects"] == ["mug"]
    assert doc["params"]["train_objects"] == ["box", "cloth"]
    info = json.loads((ds_path / INFO_PATH).read_text())
    assert info["counts"]["splits"]["given_objects"] == {"test": 2, "train": 2}
    for part, mug in (("test", True), ("train", False)):
        eps = ds.episodes.split("given_objects", part)
        wins = eps.windows(length=4, stride=1)
        objects = {ds.episodes[int(p)]["object"] for p in set(wins.episode_index.tolist())}
        assert len(wins) > 0 and objects and all((o == "mug") == mug for o in objects)
    assert verify(ds_path).ok
    res = run("info", ds_path)
    assert res.exit_code == 0 and "given_objects" in res.output, res.output


def test_same_draw_as_the_samples_and_seeded() -> None:
    """Eight objects: val is whole objects, the very ones the samples' scheme draws from the
    same objects and seed; the same episodes in any order give the same bytes."""
    objs = [f"o{i % 8}" for i in range(24)]
    table = pa.table({"episode_id": [f"e{i:02d}" for i in range(24)], "object": objs,
                      "session": ["s0"] * 24})
    sp = given_objects_episodes(table, ["o3", "o5"], seed=4)
    metas = [SampleMeta(f"x{i:02d}", "slip", i, o, 0, "s0", "", None, None, "")
             for i, o in enumerate(objs)]
    ref = given_objects_split(metas, ["o3", "o5"], seed=4)
    assert sp.params["val_objects"] == ref.params["val_objects"] and sp.params["val_objects"]
    assert sp.params["held_out_objects"] == ["o3", "o5"]
    of = dict(zip(table.column("episode_id").to_pylist(), objs, strict=True))
    for part, ids in sp.parts.items():
        whole = {o for o in objs if any(of[i] == o for i in ids)}
        assert all(of[i] in whole for i in of if of[i] in whole) and (
            sorted(i for i in of if of[i] in whole) == sorted(ids)), part
    back = given_objects_episodes(table.take(pa.array(list(range(23, -1, -1)))), ["o5", "o3"],
                                  seed=4)
    assert back.to_bytes() == sp.to_bytes()


@pytest.mark.parametrize(("held", "want"), [
    (["Mug"], "1 listed object(s) have no episode, first 'Mug' (differs in case from mug)"),
    (["mug", "box", "cloth"], "holds out every object"),
])
def test_a_list_that_does_not_fit_is_one_line_and_resumable(tmp_path: Path, held: list[str],
                                                            want: str) -> None:
    """Refused at finish in one line naming the dataset; nothing at OUT, every episode kept:
    resumed with the right list, the dataset finishes."""
    out = tmp_path / "ds"
    with pytest.raises(VtsError) as e:
        write_takes(out, takes(), holdout_objects=held)
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(str(out)) and want in msg, msg
    assert not out.exists()
    write_takes(out, takes(), holdout_objects=["box"], resume=True)
    assert vtsbench.load(out).split_file("given_objects").parts["test"] == ["episode-000001"]


@pytest.mark.parametrize(("held", "want"), [
    ([], "non-empty list"), ("mug", "non-empty list"), (["mug", "mug"], "'mug' listed twice"),
    (["mug", ""], "is not a non-empty text"), (["a\nb"], "control characters"),
])
def test_a_bad_list_is_refused_at_create(tmp_path: Path, held: object, want: str) -> None:
    with pytest.raises(VtsError) as e:
        vtsbench.create(tmp_path / "ds", holdout_objects=held)  # type: ignore[arg-type]
    msg = str(e.value)
    assert "\n" not in msg and want in msg and "holdout_objects" in msg, msg
    assert not (tmp_path / "ds").exists()


def test_with_samples_both_hold_out_the_same_objects(tmp_path: Path) -> None:
    w = _write_with_samples(tmp_path / "ds", holdout_objects=["cloth"])
    out = w.finish()
    ds = vtsbench.load(out)
    assert {"given_objects", "episode_given_objects"} <= set(ds.splits)
    smp, eps = ds.split_file("given_objects"), ds.split_file("episode_given_objects")
    assert (smp.kind, eps.kind) == ("slip", EPISODE)
    assert smp.params["held_out_objects"] == eps.params["held_out_objects"] == ["cloth"]
    assert smp.parts["test"] == ["episode-000002-s000002"]
    assert ds.episodes.split("episode_given_objects", "test").ids == ["episode-000002"]
    assert set(ds.split("given_objects", "train").index.column("object").to_pylist()) == {
        "mug", "box"}
    assert verify(out).ok


def test_a_given_sample_split_holding_out_other_objects_is_refused(tmp_path: Path) -> None:
    """A samples' given_objects added by the caller must hold out the writer's objects."""
    w = _write_with_samples(tmp_path / "ds", holdout_objects=["cloth"])
    try:
        w.add_split(SplitFile("given_objects", "slip", "", 0,
                              {"train": ["episode-000000-s000002", "episode-000002-s000002",
                                         "episode-000003-s000002"],
                               "test": ["episode-000001-s000002"]}, ["object"],
                              {"held_out_objects": ["box"]}))
        with pytest.raises(VtsError) as e:
            w.finish()
    finally:
        w.close()
    msg = str(e.value)
    assert "\n" not in msg and "holds out box" in msg and "cloth" in msg, msg
    assert not (tmp_path / "ds").exists()


def _episodes_split(parts: dict[str, list[str]], name: str = "lab",
                    disjoint: list[str] | None = None) -> SplitFile:
    return SplitFile(name, EPISODE, "the lab's", 0, parts, disjoint or [])


def test_add_split_of_episodes(tmp_path: Path) -> None:
    """Written under its own name, counted in info.json, read by ds.episodes.split, verified;
    with samples too (format 1.3)."""
    for samples in (False, True):
        out = tmp_path / f"ds{int(samples)}"
        w = _write_with_samples(out) if samples else vtsbench.create(
            out, fps=FPS, shard_mb=SHARD_MB)
        if not samples:
            for ep in takes():
                w.add_episode(**ep)
        w.add_split(_episodes_split({"train": ["episode-000000", "episode-000001"],
                                     "test": ["episode-000002"]}, disjoint=["object"]))
        w.finish()
        ds = vtsbench.load(out)
        assert "lab" in ds.splits and ds.split_file("lab").kind == EPISODE
        assert ds.episodes.split("lab", "test").ids == ["episode-000002"]
        assert len(ds.episodes.split("lab", "train").windows(length=4)) > 0
        info = json.loads((out / INFO_PATH).read_text())
        assert info["counts"]["splits"]["lab"] == {"train": 2, "test": 1}
        assert verify(out).ok


@pytest.mark.parametrize(("parts", "rule", "name", "want"), [
    ({"train": ["episode-000000"], "test": ["episode-000009"]}, [], "lab",
     "split lab leaks: episode 'episode-000009' in test is not in the dataset"),
    ({"train": ["episode-000000", "episode-000001"], "test": ["episode-000001"]}, [], "lab",
     "episode 'episode-000001' in both train and test"),
    ({"train": ["episode-000000"], "test": ["episode-000003"]}, ["object"], "lab",
     "object 'mug' in both train and test"),
    ({"train": ["episode-000000"], "test": ["episode-000001"]}, [], "unseen_objects",
     "two splits named 'unseen_objects'"),
])
def test_add_split_of_episodes_that_leaks_is_refused(tmp_path: Path, parts: dict, rule: list,
                                                     name: str, want: str) -> None:
    w = vtsbench.create(tmp_path / "ds", fps=FPS, shard_mb=SHARD_MB)
    try:
        for ep in takes():
            w.add_episode(**ep)
        w.add_split(_episodes_split(parts, name, rule))
        with pytest.raises(VtsError) as e:
            w.finish()
    finally:
        w.close()
    msg = str(e.value)
    assert "\n" not in msg and want in msg, msg
    assert not (tmp_path / "ds").exists()


def test_add_split_refuses_an_invalid_split_at_once(tmp_path: Path) -> None:
    w = vtsbench.create(tmp_path / "ds", fps=FPS, shard_mb=SHARD_MB)
    try:
        with pytest.raises(VtsError, match="not a valid split file") as e:
            w.add_split(SplitFile("lab", "frames", "", 0, {"train": ["episode-000000"]}))
        assert "\n" not in str(e.value)
    finally:
        w.close()


def test_a_samples_build_refuses_a_split_of_episodes() -> None:
    sp = _episodes_split({"train": ["take.avi"]})
    with pytest.raises(VtsError) as e:
        check_given(sp, [], "lab.json")
    assert str(e.value).startswith("lab.json: ") and "--store episodes" in str(e.value)


def test_verify_reports_a_given_objects_split_that_leaks(ds_path: Path, tmp_path: Path) -> None:
    import shutil

    copy = tmp_path / "ds"
    shutil.copytree(ds_path, copy)
    path = copy / split_path("given_objects")
    doc = json.loads(path.read_text())
    doc["parts"]["train"] = sorted([*doc["parts"]["train"], "episode-000003"])
    doc["parts"]["test"] = ["episode-000000"]
    path.write_text(json.dumps(doc))
    problems = verify(copy).problems
    assert any("leak: given_objects: object 'mug' in both train and test" in p
               for p in problems), problems
    with pytest.raises(VtsError):  # the loader refuses it at first use
        vtsbench.load(copy).episodes.split("given_objects", "test")
