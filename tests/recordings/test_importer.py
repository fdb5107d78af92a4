"""`vtsbench manifest`: file-name patterns, windows, circles CSV, and the real folders."""

import json
import re

import pytest
from typer.testing import CliRunner

from tests.fixtures.data import frame, real_dir, write_video
from vtsbench.cli import app
from vtsbench.errors import VtsError
from vtsbench.recordings.check import check_folder
from vtsbench.recordings.importer import (
    ManifestOptions,
    build_pattern_manifest,
    compile_pattern,
    read_circles,
)
from vtsbench.recordings.manifest import load_manifest
from vtsbench.recordings.media import write_png


def test_pattern_fields_are_greedy_and_typed() -> None:
    m = compile_pattern("{object}_{take}.mov").match("scissor_blade_0.mov")
    assert m and m.group("object") == "scissor_blade" and m.group("take") == "0"
    assert compile_pattern("{object}_{take:d}.mov").match("a_b.mov") is None
    m = compile_pattern("{session}/{object}.png").match("day1/cube.png")
    assert m and m.groupdict() == {"session": "day1", "object": "cube"}
    assert compile_pattern("{object}.png").match("a/b.png") is None


@pytest.mark.parametrize("bad", ["{a}_{a}.png", "{a:x}.png", "{a}.png}"])
def test_bad_patterns(bad: str) -> None:
    with pytest.raises(VtsError, match="pattern"):
        compile_pattern(bad)


def test_videos_become_sequences_and_windows(tmp_path) -> None:
    for name in ("egg_0.avi", "egg_1.avi", "hair_brush_2.avi"):
        write_video(tmp_path / name, 10)
    m = build_pattern_manifest(tmp_path, ManifestOptions("{object}_{take:d}.avi", sensor="s"))
    assert [(e.object, e.take, e.kind) for e in m.entries] == [
        ("egg", "0", "sequence"), ("egg", "1", "sequence"), ("hair_brush", "2", "sequence")]
    assert m.sessions[0].resolution == (48, 64) and m.sessions[0].fps == 25.0
    w = build_pattern_manifest(tmp_path, ManifestOptions("{object}_{take:d}.avi", window=4,
                                                         stride=3))
    assert [(e.id, e.source.start, e.source.stop) for e in w.entries[:3]] == [
        ("egg_0-w000", 0, 4), ("egg_0-w001", 3, 7), ("egg_0-w002", 6, 10)]


def test_labels_from_names_and_bad_label(tmp_path) -> None:
    (tmp_path / "d").mkdir()
    write_png(tmp_path / "d" / "cube_slip_3.png", frame())
    m = build_pattern_manifest(tmp_path / "d", ManifestOptions("{object}_{state}_{take}.png",
                                                               kind="static"))
    assert m.entries[0].labels.state == "slip"  # check reports slip on a single frame
    write_png(tmp_path / "d" / "cube_9.png", frame())
    with pytest.raises(VtsError, match="direction '9'"):
        build_pattern_manifest(tmp_path / "d", ManifestOptions("cube_{direction}.png"))


def test_circles_csv_attaches_by_base_name(tmp_path) -> None:
    for n in ("0000", "0001", "0002"):
        write_png(tmp_path / f"{n}.png", frame())
    csv = tmp_path / "circles.csv"
    csv.write_text("img_names,center_x,center_y,radius\n/qt/0000.png,10,12,5\n0001,20,22,6\n")
    m = build_pattern_manifest(tmp_path, ManifestOptions("{name}.png", kind="press",
                                                         ball_radius_mm=3.0, circles=csv))
    circles = {e.id: e.circle for e in m.entries}
    assert circles["0000"].r == 5 and circles["0001"].x == 20 and circles["0002"] is None
    assert all(e.ball_radius_mm == 3.0 for e in m.entries)
    # names with dots: a row by stem ('a.01'), by name, or with another extension
    (tmp_path / "dots").mkdir()
    for n in ("a.01", "a.02", "a.03"):
        write_png(tmp_path / "dots" / f"{n}.png", frame())
    csv.write_text("file,x,y,r\na.01,1,1,1\na.02.png,2,2,2\nx/a.03.jpg,3,3,3\n")
    m = build_pattern_manifest(tmp_path / "dots", ManifestOptions("{name}.png", kind="press",
                                                                  ball_radius_mm=3.0,
                                                                  circles=csv))
    assert [e.circle.r for e in m.entries] == [1, 2, 3]


def test_circles_csv_attaches_by_path_among_files_of_one_name(tmp_path) -> None:
    """gs_sdk-style folders name every press gelsight.png: a row goes to the file whose path
    it shares most trailing components with, and a row that fits several files alike, or two
    rows that fit one file alike, is an error, never a guess."""
    for k in range(3):
        (tmp_path / f"b/{k}").mkdir(parents=True)
        write_png(tmp_path / f"b/{k}/gelsight.png", frame())
    opts = {"kind": "press", "ball_radius_mm": 2.0}
    csv = tmp_path / "c.csv"
    csv.write_text("file,x,y,r\n/home/lab/b/2/gelsight.png,2,2,2\nb/0/gelsight.png,1,1,1\n"
                   "1/gelsight.jpg,5,5,5\n")
    m = build_pattern_manifest(tmp_path, ManifestOptions("b/{take}/gelsight.png", circles=csv,
                                                         **opts))
    assert {e.source.path: e.circle.r for e in m.entries} == {
        "b/0/gelsight.png": 1, "b/1/gelsight.png": 5, "b/2/gelsight.png": 2}
    csv.write_text("file,x,y,r\nb/0/gelsight.png,1,1,1\n")  # the others get none
    m = build_pattern_manifest(tmp_path, ManifestOptions("b/{take}/gelsight.png", circles=csv,
                                                         **opts))
    assert [e.circle is not None for e in m.entries] == [True, False, False]
    csv.write_text("file,x,y,r\ngelsight.png,2,2,2\n")
    with pytest.raises(VtsError, match=re.escape("row 'gelsight.png' fits b/0/gelsight.png "
                                                 "and b/1/gelsight.png alike")):
        build_pattern_manifest(tmp_path, ManifestOptions("b/{take}/gelsight.png", circles=csv,
                                                         **opts))
    csv.write_text("file,x,y,r\nx/1/gelsight.png,2,2,2\ny/1/gelsight.png,3,3,3\n")
    with pytest.raises(VtsError, match=re.escape("both fit b/1/gelsight.png")):
        build_pattern_manifest(tmp_path, ManifestOptions("b/{take}/gelsight.png", circles=csv,
                                                         **opts))


@pytest.mark.parametrize(("text", "needle"), [
    ("file,x,y\n", "no 'r' column"),
    ("file,x,y,r\na.png,1,2,zero\n", "row 2: x, y and r must be numbers"),
    ("file,x,y,r\na.png,1,2,3\na.png,1,2,3\n", "row 3: 'a.png' listed twice"),
])
def test_bad_circles_csv(tmp_path, text: str, needle: str) -> None:
    p = tmp_path / "c.csv"
    p.write_text(text)
    with pytest.raises(VtsError, match=needle) as ei:
        read_circles(p)
    assert str(p) in str(ei.value)


def test_unmatched_circle_rows_and_missing_ball_radius(tmp_path) -> None:
    write_png(tmp_path / "0000.png", frame())
    csv = tmp_path / "c.csv"
    csv.write_text("file,x,y,r\n0009.png,1,2,3\n")
    with pytest.raises(VtsError, match="match no file"):
        build_pattern_manifest(tmp_path, ManifestOptions("{name}.png", kind="press",
                                                         ball_radius_mm=3, circles=csv))
    with pytest.raises(VtsError, match="--ball-radius-mm"):
        build_pattern_manifest(tmp_path, ManifestOptions("{name}.png", kind="press"))


def test_out_folder_points_back_and_refuses_overwrite(tmp_path) -> None:
    src = tmp_path / "data"
    src.mkdir()
    write_video(src / "a_0.avi", 5)
    write_png(src / "bg.png", frame())
    out = tmp_path / "man"
    runner = CliRunner()
    args = ["manifest", str(src), "--pattern", "{object}_{take}.avi", "--out", str(out),
            "--background", "bg.png", "--mm-per-px", "0.05"]
    res = runner.invoke(app, args)
    assert res.exit_code == 0, res.output
    m = load_manifest(out)
    assert m.entries[0].source.path == "../data/a_0.avi"
    assert m.sessions[0].background == "../data/bg.png" and m.sessions[0].mm_per_px == (0.05, 0.05)
    assert check_folder(out).ok
    again = runner.invoke(app, args)
    assert again.exit_code == 2 and "already exists" in again.output


def test_no_match_is_a_clear_error(tmp_path) -> None:
    res = CliRunner().invoke(app, ["manifest", str(tmp_path), "--pattern", "{x}.mov"])
    assert res.exit_code == 2 and "no file matches" in res.output and "Traceback" not in res.output


@pytest.mark.real
def test_octopi_videos_manifest_and_check(tmp_path) -> None:
    src = real_dir("octopi_videos")
    opts = ManifestOptions("{object}_{take:d}.mov", sensor="gelsight-mini", out=tmp_path)
    from vtsbench.recordings.importer import write_pattern_manifest

    m, _path = write_pattern_manifest(src, opts)
    assert len(m.entries) == len(list(src.glob("*.mov")))
    names = {e.object for e in m.entries}
    split = json.loads((src / "octopi_split.json").read_text())
    assert set(split["test"]) <= names
    rep = check_folder(tmp_path)
    assert rep.ok, rep.problems[:3]
    assert rep.n_frames > 100 * len(m.entries)


@pytest.mark.real
def test_digit_presses_with_circles(tmp_path) -> None:
    src = real_dir("digit_ball_6mm")
    opts = ManifestOptions("{name}.png", kind="press", sensor="digit", ball_radius_mm=3.0,
                           circles=src / "sphere.csv", out=tmp_path)
    m = build_pattern_manifest(src, opts)
    with_circle = [e for e in m.entries if e.circle is not None]
    assert len(m.entries) == 16 and len(with_circle) == 14
    from vtsbench.recordings.manifest import save_manifest

    save_manifest(tmp_path, m)
    rep = check_folder(tmp_path)
    assert rep.ok and any("no background" in w for w in rep.warnings)


def test_window_leaves_out_short_clips_with_a_warning(tmp_path, capsys) -> None:
    write_video(tmp_path / "egg_0.avi", 10)
    write_video(tmp_path / "egg_1.avi", 5)  # shorter than the window: left out, not an error
    write_video(tmp_path / "cup_0.avi", 8)
    said: list[str] = []
    m = build_pattern_manifest(tmp_path, ManifestOptions("{object}_{take:d}.avi", window=8),
                               warn=said.append)
    assert [e.id for e in m.entries] == ["cup_0-w000", "egg_0-w000"]
    assert said == ["egg_1.avi: 5 frames, fewer than --window 8: left out",
                    "left out 1 of 3 matched files, shorter than --window 8"]
    res = CliRunner().invoke(app, ["manifest", str(tmp_path), "--pattern",
                                   "{object}_{take:d}.avi", "--window", "8"])
    assert res.exit_code == 0, res.output
    assert "egg_1.avi: 5 frames" in res.output and "wrote" in res.output
    assert len(load_manifest(tmp_path).entries) == 2
    with pytest.raises(VtsError, match="every matched file is shorter"):
        build_pattern_manifest(tmp_path, ManifestOptions("egg_1.avi", window=8))
