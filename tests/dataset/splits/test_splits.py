"""Split schemes: guarantees checked by leak_check, determinism, edge cases, split files."""

from __future__ import annotations

import dataclasses
import hashlib
import random
from collections import Counter

import pytest

from tests.fixtures.samples import OBJECTS, RES, SESSIONS, synth
from vtsbench.dataset import splits as sp
from vtsbench.dataset.format.records import SampleMeta, SplitFile, schema_errors
from vtsbench.errors import VtsError


@pytest.fixture(scope="module")
def samples() -> list[SampleMeta]:
    return synth()


@pytest.fixture(scope="module")
def report(samples) -> sp.SplitReport:
    return sp.make_splits(samples, resolution=RES)


def by_id(samples: list[SampleMeta]) -> dict[str, SampleMeta]:
    return {s.sample_id: s for s in samples}


def values(split: SplitFile, samples: list[SampleMeta], part: str, key: str) -> set:
    m = by_id(samples)
    return {getattr(m[i], key) for i in split.parts[part]}


def test_every_scheme_is_made_valid_and_clean(report, samples) -> None:
    assert [s.name for s in report.splits] == list(sp.SCHEMES)
    assert report.skipped == {}
    for split in report.splits:
        assert schema_errors(split.to_dict(), "split") == []
        assert sp.leak_check(split, samples) == [], split.name
        assert all(split.parts.values()), split.name


def test_same_bytes_whatever_the_input_order(report, samples) -> None:
    shuffled = list(samples)
    random.Random(7).shuffle(shuffled)
    again = sp.make_splits(shuffled, resolution=RES)
    assert [s.to_bytes() for s in again.splits] == [s.to_bytes() for s in report.splits]
    other = sp.make_splits(samples, seed=1, resolution=RES)
    assert other.get("unseen_objects").to_bytes() != report.get("unseen_objects").to_bytes()


def test_unseen_objects_holds_out_whole_objects_balanced(report, samples) -> None:
    split = report.get("unseen_objects")
    held = split.params["held_out_objects"]
    assert len(held) == 5 == split.params["k"]
    assert values(split, samples, "test", "object") == set(held)
    seen = values(split, samples, "train", "object") | values(split, samples, "val", "object")
    assert not seen & set(held) and len(seen) == 10
    states = Counter(by_id(samples)[i].state for i in split.parts["test"])
    # 300 held-out samples at 50/30/20 %: every state cut to the 60 slips
    assert states == {"static": 60, "press": 60, "slip": 60}
    assert split.params["dropped_for_balance"] == {"static": 90, "press": 30, "slip": 0}
    n_seen = 600
    assert len(split.parts["val"]) == 60 and len(split.parts["train"]) == n_seen - 60
    assert split.disjoint == ["object:test"]


def test_seen_parts_are_whole_sessions_of_seen_objects(report, samples) -> None:
    split = report.get("seen")
    held = set(report.get("unseen_objects").params["held_out_objects"])
    sessions = [values(split, samples, p, "session") for p in ("train", "val", "test")]
    assert all(len(s) == 1 for s in sessions) and set.union(*sessions) == set(SESSIONS)
    for p in split.parts:
        assert not values(split, samples, p, "object") & held
    assert split.params["groups"] == 30 == split.params["groups_in_every_part"]
    assert split.params["missing"] == []
    assert sum(map(len, split.parts.values())) == 600


def test_seen_with_two_sessions_drops_val_and_with_one_raises() -> None:
    two = synth(300, 0, sessions=("a", "b"))
    split = sp.seen_split(two)
    assert set(split.parts) == {"train", "test"} and split.params["val"].startswith("dropped")
    assert sp.leak_check(split, two) == []
    with pytest.raises(VtsError, match=r"seen: every sample comes from one session \('a'\)"):
        sp.seen_split(synth(90, 0, sessions=("a",)))


def test_seen_stratifies_when_sessions_differ() -> None:
    # obj01 is only in day1..day3 but obj00 also in day4: the chosen parts still hold both
    ss = synth(180, 0, objects=("obj00", "obj01"), sessions=("day1", "day2", "day3", "day4"))
    ss = [s for s in ss if not (s.object == "obj01" and s.session == "day4")]
    split = sp.seen_split(ss, seed=3)
    assert split.params["groups_in_every_part"] == split.params["groups"] == 6
    assert sp.leak_check(split, ss) == []


def test_object_folds_cover_every_object_once_balanced(report, samples) -> None:
    split = report.get("object_folds")
    assert sorted(split.parts) == [f"fold{j}" for j in range(5)]
    objs = [values(split, samples, p, "object") for p in split.parts]
    assert sorted(o for s in objs for o in s) == sorted(OBJECTS)
    assert [len(v) for v in split.parts.values()] == [180] * 5
    ids = [i for v in split.parts.values() for i in v]
    assert sorted(ids) == sorted(s.sample_id for s in samples if s.kind == "slip")
    many = sp.object_folds_split(samples, folds=20)
    assert many.params["k"] == 15 and sp.leak_check(many, samples) == []


def test_static_sessions_hold_out_whole_sessions(report, samples) -> None:
    split = report.get("static_sessions")
    assert split.kind == "static" and set(split.parts) == {"train", "val", "test"}
    sessions = [values(split, samples, p, "session") for p in split.parts]
    assert sum(map(len, sessions)) == 3 == len(set.union(*sessions))
    assert all(values(split, samples, p, "object") == set(OBJECTS) for p in split.parts)


def test_static_locations_holds_out_the_middle_band(report, samples) -> None:
    split = report.get("static_locations")
    m = by_id(samples)
    lo, hi = RES[1] / 3, 2 * RES[1] / 3
    assert all(lo <= m[i].contact_x_px < hi for i in split.parts["test"])
    rest = [m[i] for p in ("train", "val") for i in split.parts[p]]
    assert not any(s.contact_x_px is not None and lo <= s.contact_x_px < hi for s in rest)
    assert split.params["unknown_location_in_train"] == 12
    assert sum(m[i].contact_x_px is None for i in split.parts["train"]) == 12
    assert sum(map(len, split.parts.values())) == 300


def test_static_locations_needs_the_frame_width(samples) -> None:
    rep = sp.make_splits(samples)
    assert "pass resolution" in rep.skipped["static_locations"]
    assert len(rep.splits) == 4


def test_leaky_splits_are_caught(report, samples) -> None:
    good = report.get("unseen_objects")
    parts = {p: list(v) for p, v in good.parts.items()}
    moved = parts["test"].pop()
    parts["train"].append(moved)
    obj = by_id(samples)[moved].object
    leaky = dataclasses.replace(good, parts=parts)
    assert sp.leak_check(leaky, samples) == [
        f"unseen_objects: object {obj!r} in both train and test"]
    parts["val"] += [parts["train"][0], "ghost", "static-0001"]
    problems = sp.leak_check(dataclasses.replace(good, parts=parts), samples)
    assert f"unseen_objects: sample {parts['train'][0]!r} in both train and val" in problems
    assert "unseen_objects: sample 'ghost' in val is not in the dataset" in problems
    assert ("unseen_objects: sample 'static-0001' in val is a static sample in a slip split"
            in problems)
    seen = report.get("seen")
    mixed = {p: list(v) for p, v in seen.parts.items()}
    mixed["test"].append(mixed["train"].pop())
    found = sp.leak_check(dataclasses.replace(seen, parts=mixed), samples)
    session = by_id(samples)[mixed["test"][-1]].session
    assert found == [f"seen: session {session!r} in both train and test"]


def test_leaky_location_split_is_caught(report, samples) -> None:
    good = report.get("static_locations")
    parts = {p: list(v) for p, v in good.parts.items()}
    parts["train"].append(parts["test"].pop())
    assert sp.leak_check(dataclasses.replace(good, parts=parts), samples) == [
        f"static_locations: location {sp.BAND!r} in both train and test"]
    no_band = dataclasses.replace(good, params={})
    assert sp.leak_check(no_band, samples) == [
        "static_locations: rule 'location:test' needs params.location.bands_px"]


def test_one_object_skips_only_what_needs_several() -> None:
    ss = synth(90, 30, objects=("gear",))
    with pytest.raises(VtsError, match="unseen_objects: needs at least 2 objects"):
        sp.unseen_objects_split(ss)
    rep = sp.make_splits(ss, resolution=RES)
    assert set(rep.skipped) == {"unseen_objects", "object_folds"}
    assert "found only 'gear'" in rep.skipped["object_folds"]
    assert [s.name for s in rep.splits] == ["seen", "static_sessions", "static_locations"]
    assert rep.get("seen").params["seen_objects"] == ["gear"]
    for split in rep.splits:
        assert sp.leak_check(split, ss) == []


def test_one_state_only_gives_a_test_of_that_state() -> None:
    ss = synth(450, 0, states=("press",))
    split = sp.unseen_objects_split(ss)
    held = split.params["held_out_objects"]
    assert split.params["test_states"] == ["press"] and split.params["missing_states"] == []
    assert len(split.parts["test"]) == sum(s.object in held for s in ss)


def test_unknown_states_stay_out_of_test() -> None:
    ss = [dataclasses.replace(s, state=None, state_idx=None, direction=None)
          if s.state == "static" else s for s in synth(900, 0)]
    split = sp.unseen_objects_split(ss)
    assert split.params["test_states"] == ["press", "slip"]
    assert split.params["missing_states"] == []
    assert split.params["dropped_unknown_state"] == 150
    assert sp.leak_check(split, ss) == []


@pytest.mark.parametrize(("kw", "kept", "reason"), [
    ({"n_slip": 0}, {"static_sessions", "static_locations"}, "no slip samples"),
    ({"n_static": 0}, {"unseen_objects", "seen", "object_folds"}, "no static samples"),
    ({"n_slip": 0, "n_static": 0}, set(), "no "),
])
def test_missing_kinds_are_skipped_and_reported(kw, kept, reason) -> None:
    rep = sp.make_splits(synth(**kw), resolution=RES)
    assert {s.name for s in rep.splits} == kept
    assert set(rep.skipped) == set(sp.SCHEMES) - kept
    assert all(reason in why for why in rep.skipped.values())


def test_k_must_leave_a_seen_object(samples) -> None:
    with pytest.raises(VtsError, match="cannot hold out 15 of 15 objects"):
        sp.make_splits(samples, unseen_k=15)
    with pytest.raises(VtsError, match="cannot hold out 20 of 15"):
        sp.unseen_objects_split(samples, k=20)
    split = sp.unseen_objects_split(samples, k=14)
    assert len(split.params["seen_objects"]) == 1 and sp.leak_check(split, samples) == []


@pytest.mark.parametrize("kw", [
    {"seed": -1}, {"unseen_k": 0}, {"val_fraction": 1.0}, {"folds": 1},
    {"location_bands": [(0.5, 0.2)]}, {"test_fraction": 0.95},
])
def test_bad_parameters_raise(samples, kw) -> None:
    with pytest.raises(VtsError):
        sp.make_splits(samples, **kw)


def test_repeated_ids_are_refused(samples) -> None:
    with pytest.raises(VtsError, match="appears twice"):
        sp.make_splits([*samples, samples[0]])


def test_no_val_when_fraction_is_zero(samples) -> None:
    rep = sp.make_splits(samples, val_fraction=0.0, resolution=RES)
    assert not any("val" in s.parts for s in rep.splits)
    assert all(sp.leak_check(s, samples) == [] for s in rep.splits)


def test_write_and_read_split_files(tmp_path, report) -> None:
    shas = sp.write_splits(tmp_path / "splits", report.splits)
    assert list(shas) == list(sp.SCHEMES)
    for split in report.splits:
        path = tmp_path / "splits" / f"{split.name}.json"
        assert hashlib.sha256(path.read_bytes()).hexdigest() == shas[split.name] == split.sha256()
        assert sp.read_split(path, shas[split.name]) == split
    path = tmp_path / "splits" / "seen.json"
    path.write_text(path.read_text().replace('"day1"', '"day9"'))
    with pytest.raises(VtsError) as ei:
        sp.read_split(path, shas["seen"])
    msg = str(ei.value)
    assert "seen.json" in msg and "sha256 mismatch" in msg and "\n" not in msg
    assert sp.read_split(path).params["sessions"]  # no checksum asked: read as is
    path.write_text("{")
    with pytest.raises(VtsError, match="invalid JSON"):
        sp.read_split(path)
    with pytest.raises(VtsError, match="not found"):
        sp.read_split(tmp_path / "nope.json")


def test_write_refuses_invalid_or_repeated_splits(tmp_path, report) -> None:
    bad = dataclasses.replace(report.splits[0], kind="press")
    with pytest.raises(ValueError, match="invalid split"):
        sp.write_splits(tmp_path, [bad])
    with pytest.raises(ValueError, match="two splits"):
        sp.write_splits(tmp_path, [report.splits[0], report.splits[0]])


def test_unseen_objects_val_keeps_the_windows_of_a_take_together() -> None:
    """Windows cut from one take (source `path[a:b]`) never straddle train and val."""
    base = synth(n_slip=450, n_static=0)
    # three consecutive samples share a take, as windows of one video do
    windows = [dataclasses.replace(s, source=f"rec/take{i // 3}.avi[{8 * (i % 3)}:"
                                             f"{8 * (i % 3) + 8}]")
               for i, s in enumerate(base)]
    split = sp.unseen_objects_split(windows, seed=3)
    take = {s.sample_id: sp.schemes.take_of(s.source) for s in windows}
    train = {take[i] for i in split.parts["train"]}
    val = {take[i] for i in split.parts["val"]}
    assert val and not train & val
    assert 0.5 * 0.1 * 450 < len(split.parts["val"]) < 2 * 0.1 * 450


def test_unseen_objects_val_of_one_sample_takes_is_unchanged(samples) -> None:
    """Every take one sample: the val cut is the per-sample draw it always was."""
    a = sp.unseen_objects_split(samples, seed=5)
    one = [dataclasses.replace(s, source=f"rec/{s.sample_id}.avi[0:8]") for s in samples]
    b = sp.unseen_objects_split(one, seed=5)
    assert a.parts == b.parts
    assert sp.schemes.take_of("a/b[c].avi[3:11]") == "a/b[c].avi"
    assert sp.schemes.take_of("rec/s1.png") == "rec/s1.png"


def test_unseen_objects_val_leaves_a_take_to_train_and_sources_may_be_empty(samples) -> None:
    """A seen set of one take keeps it in train; samples without a source are takes of their
    own (the episode splits' records)."""
    one_take = [dataclasses.replace(s, source=f"rec/all.avi[{8 * i}:{8 * i + 8}]")
                for i, s in enumerate(samples)]
    split = sp.unseen_objects_split(one_take, seed=5)
    assert split.parts["train"] and "val" not in split.parts
    blank = [dataclasses.replace(s, source="") for s in samples]
    assert sp.unseen_objects_split(blank, seed=5).parts == sp.unseen_objects_split(
        samples, seed=5).parts
