"""The typed manifest classes mirror schemas/recording.schema.json and round-trip through it."""

import dataclasses
import json

import pytest

from vtsbench.errors import VtsError
from vtsbench.recordings import manifest as mf


def _props(name: str) -> set[str]:
    return set(mf.schema()["$defs"][name]["properties"])


@pytest.mark.parametrize(("cls", "name"), [
    (mf.Session, "session"), (mf.Entry, "entry"), (mf.Source, "source"), (mf.Labels, "labels"),
    (mf.Circle, "circle"), (mf.Mount, "mount"),
])
def test_classes_mirror_schema(cls, name) -> None:
    assert {f.name for f in dataclasses.fields(cls)} == _props(name)


def test_manifest_fields_are_top_level_properties() -> None:
    top = set(mf.schema()["properties"])
    assert {f.name for f in dataclasses.fields(mf.Manifest)} | {"format"} == top


def test_round_trip_validates(make_recordings) -> None:
    root, m = make_recordings()
    doc = json.loads((root / mf.MANIFEST_NAME).read_text())
    assert mf.schema_errors(doc) == []
    again = mf.Manifest.from_dict(doc)
    assert again == m
    assert again.to_dict() == doc


def test_anisotropic_scale_and_unknowns_round_trip() -> None:
    s = mf.Session("a", "x", (10, 20), (0.03, 0.04), None, None)
    d = s.to_dict()
    assert d["mm_per_px"] == [0.03, 0.04] and d["fps"] is None
    assert mf.Session.from_dict(d) == s
    s2 = mf.Session("b", "x", (10, 20))
    assert mf.Session.from_dict(s2.to_dict()) == s2


@pytest.mark.parametrize(("mutate", "needle"), [
    (lambda d: d["entries"][1]["labels"].update(direction=8), "maximum"),
    (lambda d: d["entries"][1]["labels"].update(state="slide"), "labels.state"),
    (lambda d: d["entries"][0].update(kind="movie"), "kind"),
    (lambda d: d["sessions"][0].update(resolution=[48]), "resolution"),
    (lambda d: d["entries"][0]["source"].update(path="/abs/file.png"), "source.path"),
    (lambda d: d["entries"][0].update(colour="red"), "colour"),
    (lambda d: d["sessions"][0].update(mm_per_px=-1), "mm_per_px"),
])
def test_schema_errors_name_the_place(make_recordings, mutate, needle) -> None:
    root, _ = make_recordings()
    doc = json.loads((root / mf.MANIFEST_NAME).read_text())
    mutate(doc)
    errs = mf.schema_errors(doc)
    assert errs and any(needle in e for e in errs), errs


def test_load_rejects_invalid_json_in_one_line(tmp_path) -> None:
    (tmp_path / mf.MANIFEST_NAME).write_text("{not json")
    with pytest.raises(VtsError) as ei:
        mf.load_manifest(tmp_path)
    assert "recordings.json" in str(ei.value) and "\n" not in str(ei.value)


def test_missing_manifest_and_folder(tmp_path) -> None:
    with pytest.raises(VtsError, match=r"no recordings\.json"):
        mf.load_manifest(tmp_path)
    with pytest.raises(VtsError, match="not a folder"):
        mf.load_manifest(tmp_path / "nope")


def test_mount_maps_stage_motion_to_image() -> None:
    assert mf.Mount().to_image(1.0, 0.0) == (1.0, 0.0)
    x, y = mf.Mount(rotation_deg=90).to_image(1.0, 0.0)
    assert abs(x) < 1e-12 and abs(y - 1.0) < 1e-12
    x, y = mf.Mount(mirror=True).to_image(1.0, 2.0)
    assert (x, y) == (-1.0, 2.0)


def test_save_refuses_invalid_manifest(tmp_path) -> None:
    m = mf.Manifest(sessions=[mf.Session("s", "x", (4, 4))],
                    entries=[mf.Entry("bad id!", "static", "s", mf.Source("a.png"))])
    with pytest.raises(VtsError, match="invalid manifest"):
        mf.save_manifest(tmp_path, m)
    assert not (tmp_path / mf.MANIFEST_NAME).exists()
