"""`vtsbench build --store episodes`: each take stored once through the episode writer, the
samples views of it (format 1.3), equal to today's build sample for sample (every array, the
index columns, the split files); resumable after a failure at every write and rename; bad
input one line."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest

import vtsbench
from tests.fixtures.cli import clean, run
from tests.fixtures.datasets import SHARD_MB, tree_bytes
from tests.fixtures.faults import Crash, FailingOs, count_renames
from vtsbench import atomic
from vtsbench.dataset.build import BuildOptions, build
from vtsbench.dataset.build.staging import partial_path
from vtsbench.errors import VtsError

VIEW_COLUMNS = ["episode_index", "frame_row"]


@pytest.fixture(scope="module")
def episodes_built(sim_recordings: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("build-episodes") / "ds"
    build(sim_recordings, out, BuildOptions(shard_mb=SHARD_MB, store="episodes"))
    return out


def _same_value(a: Any, b: Any) -> bool:
    if isinstance(a, np.ndarray):
        return a.dtype == b.dtype and np.array_equal(a, b)
    return a == b or (a != a and b != b)  # NaN


def test_equals_the_samples_build_sample_for_sample(built: Path, episodes_built: Path) -> None:
    a, b = vtsbench.load(built), vtsbench.load(episodes_built)
    for kind in ("static", "slip"):
        va, vb = getattr(a, kind), getattr(b, kind)
        assert len(va) == len(vb) > 0
        for i in range(len(va)):
            x, y = va[i], vb[i]
            assert set(x) <= set(y), kind
            for k in x:
                assert _same_value(x[k], y[k]), (kind, i, k)
        ta = pq.read_table(built / f"index/{kind}.parquet")
        tb = pq.read_table(episodes_built / f"index/{kind}.parquet")
        assert tb.drop_columns(VIEW_COLUMNS).equals(ta)
    splits_a = sorted(p.name for p in (built / "meta/splits").glob("*.json"))
    for name in splits_a:  # the same split files, byte for byte
        assert (built / "meta/splits" / name).read_bytes() == (
            episodes_built / "meta/splits" / name).read_bytes(), name
    assert set(b.splits) == {*a.splits, "episode_unseen_objects", "episode_unseen_sessions"}


def test_layout_info_and_verify(episodes_built: Path, sim_recordings: Path) -> None:
    from vtsbench.dataset.tools.verify import verify

    info = json.loads((episodes_built / "meta/info.json").read_text())
    assert info["format_version"] == "1.3" and info["sample_storage"] == "episodes"
    assert info["created_by"] == "vtsbench build --store episodes"
    assert info["calibration"]["method"] == "lut" and info["build"]["store"] == "episodes"
    assert info["build"]["solver"] == "dct"
    assert not (episodes_built / "data/slip.zarr").exists()
    assert not (episodes_built / "data/static.zarr").exists()
    ds = vtsbench.load(episodes_built)
    # one episode a take (a sequence folder or a static image), named by its source
    ids = ds.episodes.ids
    slip = pq.read_table(episodes_built / "index/slip.parquet").to_pylist()
    assert len(ids) == len(ds.static) + len(ds.slip)
    for r in slip:  # the frames' labels come from their sample
        ep = ds.episodes[r["episode_index"]]
        assert ep["episode_id"] == r["source"].rsplit("[", 1)[0]
        want = ["static", "press", "slip"].index(r["state"]) if r["state"] else -1
        assert ep["state"].tolist() == [want] * 8
    assert verify(episodes_built).ok


def test_two_workers_give_the_same_bytes(episodes_built: Path, sim_recordings: Path,
                                         tmp_path: Path) -> None:
    out = tmp_path / "ds"
    res = build(sim_recordings, out, BuildOptions(shard_mb=SHARD_MB, store="episodes",
                                                   workers=2))
    assert res.takes == 15 and res.shards_built == 15
    assert tree_bytes(out) == tree_bytes(episodes_built)


def test_a_failure_at_every_write_and_rename_then_resume(make_recordings, tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch
                                                         ) -> None:
    root, _ = make_recordings()
    opts = BuildOptions(depth=False, store="episodes", shard_mb=0.05)
    ref = tmp_path / "ref" / "ds"
    steps = count_renames(monkeypatch, lambda: build(root, ref, opts))
    assert steps > 10
    for at in range(1, steps + 1):
        out = tmp_path / f"run{at}" / "ds"
        monkeypatch.setattr(atomic, "os", FailingOs(at))
        with pytest.raises(Crash):
            build(root, out, opts)
        monkeypatch.setattr(atomic, "os", os)
        assert not out.exists(), f"step {at}: OUT exists after a failed build"
        logged: list[str] = []
        build(root, out, opts, log=logged.append)
        assert tree_bytes(out) == tree_bytes(ref), f"step {at}: other bytes after resume"
        assert not partial_path(out).exists()
    # a rerun with other options does not take over the partial build
    monkeypatch.setattr(atomic, "os", FailingOs(steps - 3))
    with pytest.raises(Crash):
        build(root, tmp_path / "other" / "ds", opts)
    monkeypatch.setattr(atomic, "os", os)
    with pytest.raises(VtsError, match="options or recordings differ"):
        build(root, tmp_path / "other" / "ds", BuildOptions(depth=False, store="episodes",
                                                             shard_mb=0.05, frames=4))


def test_resume_says_so_and_skips_the_saved_takes(make_recordings, tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    root, _ = make_recordings()
    opts = BuildOptions(depth=False, store="episodes", shard_mb=0.05)
    out = tmp_path / "ds"
    monkeypatch.setattr(atomic, "os", FailingOs(12))  # past the first takes
    with pytest.raises(Crash):
        build(root, out, opts)
    monkeypatch.setattr(atomic, "os", os)
    logged: list[str] = []
    res = build(root, out, opts, log=logged.append)
    assert res.shards_kept > 0 and res.shards_kept + res.shards_built == res.takes == 3
    assert logged and logged[0].startswith(f"resuming .ds.partial: {res.shards_kept} of 3 "
                                           "takes"), logged


def test_refusals_are_one_line(make_recordings, tmp_path: Path) -> None:
    from vtsbench.recordings.manifest import load_manifest, save_manifest

    root, _ = make_recordings()
    with pytest.raises(VtsError) as e:
        build(root, tmp_path / "a", BuildOptions(depth=False, store="episodes",
                                                 scheduler="local"))
    assert "--scheduler" in str(e.value) and "\n" not in str(e.value)
    with pytest.raises(VtsError, match="--store must be one of samples, episodes"):
        build(root, tmp_path / "b", BuildOptions(depth=False, store="frames"))
    m = load_manifest(root)  # two entries of one video, of two objects
    e0 = next(x for x in m.entries if x.id == "seq-1")
    from dataclasses import replace

    from vtsbench.recordings.manifest import Source

    m.entries.append(replace(e0, id="seq-3", object="cube", source=Source("take.avi", start=2,
                                                                          stop=10)))
    save_manifest(root, m)
    with pytest.raises(VtsError) as e:
        build(root, tmp_path / "c", BuildOptions(depth=False, store="episodes"))
    msg = str(e.value)
    assert "\n" not in msg and "seq-1 and seq-3" in msg and "differ in object" in msg, msg
    assert not (tmp_path / "c").exists()


def test_cli_store_episodes(make_recordings, tmp_path: Path) -> None:
    root, _ = make_recordings()
    res = run("build", root, tmp_path / "ds", "--no-depth", "--store", "episodes", "--quiet")
    assert res.exit_code == 0, res.output
    assert "takes built 3" in " ".join(res.output.split())
    assert json.loads((tmp_path / "ds/meta/info.json").read_text())["format_version"] == "1.3"
    res = run("build", root, tmp_path / "ds2", "--no-depth", "--store", "episodes",
              "--scheduler", "local", "--quiet")
    clean(res, 2, "--scheduler")


def _two_slip_objects(make_recordings) -> Path:
    """The tiny recordings with the image-folder sequence made of another object (ball): slip
    objects gear and ball, static object cube; takes static.png, take.avi and seqdir."""
    from dataclasses import replace

    from vtsbench.recordings.manifest import load_manifest, save_manifest

    root, _ = make_recordings()
    m = load_manifest(root)
    m.entries = [replace(e, object="ball") if e.id == "seq-2" else e for e in m.entries]
    save_manifest(root, m)
    return root


def test_holdout_objects_makes_both_given_splits(make_recordings, tmp_path: Path) -> None:
    """--holdout-objects with --store episodes: the samples' given_objects (byte for byte a
    samples build's) and episode_given_objects over the takes, holding out the same objects;
    verify checks both and the episodes' test windows hold only those objects."""
    from vtsbench.dataset.tools.verify import verify

    root = _two_slip_objects(make_recordings)
    held = tmp_path / "test_objects.txt"
    held.write_text("# the lab's test objects\ngear\n")
    opts = BuildOptions(depth=False, store="episodes", holdout_objects=held)
    out = build(root, tmp_path / "eps", opts).out
    ref = build(root, tmp_path / "samples", replace_opts(opts, store="samples")).out
    assert (out / "meta/splits/given_objects.json").read_bytes() == (
        ref / "meta/splits/given_objects.json").read_bytes()
    ds = vtsbench.load(out)
    assert {"given_objects", "episode_given_objects"} <= set(ds.splits)
    eps, smp = ds.split_file("episode_given_objects"), ds.split_file("given_objects")
    assert (eps.kind, smp.kind) == ("episode", "slip")
    assert eps.params["held_out_objects"] == smp.params["held_out_objects"] == ["gear"]
    assert eps.params["source"] == "test_objects.txt"
    assert eps.parts["test"] == ["take.avi"]
    assert sorted(eps.parts["train"]) == ["seqdir", "static.png"]
    test = ds.episodes.split("episode_given_objects", "test")
    wins = test.windows(length=4, stride=2)
    assert len(wins) > 0 and {test[i]["object"] for i in range(len(test))} == {"gear"}
    assert set(ds.split("given_objects", "test").index.column("object").to_pylist()) == {
        "gear"}
    info = json.loads((out / "meta/info.json").read_text())
    assert info["counts"]["splits"]["episode_given_objects"] == {"test": 1, "train": 2}
    assert verify(out).ok


def replace_opts(opts: BuildOptions, **kw: Any) -> BuildOptions:
    from dataclasses import replace

    return replace(opts, **kw)


def _episode_split(path: Path, parts: dict[str, list[str]], name: str = "lab_takes",
                   disjoint: list[str] | None = None) -> Path:
    path.write_text(json.dumps({"name": name, "kind": "episode", "description": "the lab's",
                                "seed": 0, "parts": parts, "disjoint": disjoint or [],
                                "params": {}}))
    return path


def test_split_file_of_episodes(make_recordings, tmp_path: Path,
                                monkeypatch: pytest.MonkeyPatch) -> None:
    """--split-file of kind episode: parts of take ids, written under its name and read by
    ds.episodes.split; an unknown take, a take in two parts or a broken rule is refused in one
    line naming the file before any frame is decoded; a samples build refuses it."""
    from vtsbench.dataset.tools.verify import verify

    root = _two_slip_objects(make_recordings)
    good = _episode_split(tmp_path / "good.json", {"train": ["seqdir", "static.png"],
                                                   "test": ["take.avi"]}, disjoint=["object"])
    res = run("build", root, tmp_path / "ds", "--no-depth", "--store", "episodes",
              "--split-file", good, "--quiet")
    assert res.exit_code == 0, res.output
    ds = vtsbench.load(tmp_path / "ds")
    assert "lab_takes" in ds.splits and ds.split_file("lab_takes").kind == "episode"
    assert ds.episodes.split("lab_takes", "test").ids == ["take.avi"]
    assert verify(tmp_path / "ds").ok
    info = run("info", tmp_path / "ds")
    assert info.exit_code == 0 and "lab_takes" in info.output, info.output
    bad = {
        "unknown": ({"train": ["seqdir"], "test": ["nope.avi"]}, [], "'nope.avi' in test is "
                    "not in the dataset"),
        "twice": ({"train": ["seqdir", "take.avi"], "test": ["take.avi"]}, [],
                  "episode 'take.avi' in both train and test"),
        "rule": ({"train": ["seqdir"], "test": ["static.png", "take.avi"]}, ["session"],
                 "session 's0' in both train and test"),
    }
    from vtsbench.dataset.build import episodes_build

    def no_decoding(task: Any) -> Any:
        raise AssertionError("a take was decoded")

    monkeypatch.setattr(episodes_build, "decode_take", no_decoding)
    for name, (parts, rule, want) in bad.items():
        f = _episode_split(tmp_path / f"{name}.json", parts, disjoint=rule)
        out = tmp_path / f"ds-{name}"
        with pytest.raises(VtsError) as e:
            build(root, out, BuildOptions(depth=False, store="episodes", split_files=(f,)))
        msg = str(e.value)
        assert "\n" not in msg and msg.startswith(str(f)) and want in msg, msg
        assert not out.exists(), name
    taken = _episode_split(tmp_path / "taken.json", {"train": ["seqdir"]},
                           name="episode_unseen_objects")
    with pytest.raises(VtsError, match="two splits named 'episode_unseen_objects'"):
        build(root, tmp_path / "ds-taken", BuildOptions(depth=False, store="episodes",
                                                        split_files=(taken,)))
    res = run("build", root, tmp_path / "ds-samples", "--no-depth", "--split-file", good,
              "--quiet")
    clean(res, 2, "good.json", "split of episodes", "--store episodes")
