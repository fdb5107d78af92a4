"""`vtsbench check` lists every problem, each with the entry and file named."""

import json

import pytest
from typer.testing import CliRunner

from tests.fixtures.data import frame
from vtsbench.cli import app
from vtsbench.recordings.check import check_folder
from vtsbench.recordings.manifest import MANIFEST_NAME
from vtsbench.recordings.media import write_png


def _edit(root, fn) -> None:
    p = root / MANIFEST_NAME
    doc = json.loads(p.read_text())
    fn(doc)
    p.write_text(json.dumps(doc))


def test_valid_folder_passes(make_recordings) -> None:
    root, _ = make_recordings()
    rep = check_folder(root)
    assert rep.ok, rep.problems
    assert rep.n_entries == 4 and rep.n_frames == 1 + 8 + 8 + 1


def _problems(root) -> list[str]:
    return check_folder(root).problems


def test_missing_file(make_recordings) -> None:
    root, _ = make_recordings()
    (root / "static.png").unlink()
    assert _problems(root) == ["st-1: static.png: file not found"]


def test_unreadable_image(make_recordings) -> None:
    root, _ = make_recordings()
    (root / "press.png").write_bytes(b"\x89PNG broken")
    [p] = _problems(root)
    assert p.startswith("pr-1: press.png:") and "cannot decode image" in p


def test_undecodable_video(make_recordings) -> None:
    root, _ = make_recordings()
    (root / "take.avi").write_bytes(b"RIFF" + bytes(500))
    [p] = _problems(root)
    assert p.startswith("seq-1: take.avi:") and "video" in p


def test_frame_range_past_the_end(make_recordings) -> None:
    root, _ = make_recordings()
    _edit(root, lambda d: d["entries"][1]["source"].update(start=8, stop=16))
    [p] = _problems(root)
    assert p == "seq-1: take.avi: frame range [8, 16) past the end (12 frames)"


def test_frame_range_past_the_end_of_an_image_folder(make_recordings) -> None:
    root, _ = make_recordings()
    _edit(root, lambda d: d["entries"][2]["source"].update(stop=9))
    assert _problems(root) == ["seq-2: seqdir: frame range [0, 9) past the end (8 frames)"]


def test_wrong_resolution(make_recordings) -> None:
    root, _ = make_recordings()
    write_png(root / "static.png", frame(40, 64))
    assert _problems(root) == ["st-1: static.png: wrong resolution 40x64, session s0 says 48x64"]


def test_label_out_of_range(make_recordings) -> None:
    root, _ = make_recordings()
    _edit(root, lambda d: d["entries"][1]["labels"].update(direction=9))
    [p] = _problems(root)
    assert "recordings.json" in p and "seq-1" in p and "direction" in p and "maximum of 7" in p


def test_direction_on_non_slip_entry(make_recordings) -> None:
    root, _ = make_recordings()
    _edit(root, lambda d: d["entries"][2]["labels"].update(direction=3))
    assert _problems(root) == ["seq-2: seqdir: direction 3 on a non-slip entry (state press)"]


def test_direction_on_single_frame(make_recordings) -> None:
    root, _ = make_recordings()
    _edit(root, lambda d: d["entries"][0]["labels"].update(direction=1))
    assert _problems(root) == ["st-1: static.png: direction 1 on a static entry "
                               "(only sequences slip)"]


def test_direction_disagreeing_with_motion(make_recordings) -> None:
    root, _ = make_recordings()
    _edit(root, lambda d: d["entries"][1]["labels"].update(direction=0))
    [p] = _problems(root)
    assert "disagrees with motion_mm" in p and "(class 2)" in p


def test_press_without_ball_radius(make_recordings) -> None:
    root, _ = make_recordings()
    _edit(root, lambda d: d["entries"][3].pop("ball_radius_mm"))
    assert _problems(root) == ["pr-1: press.png: press without a ball radius (ball_radius_mm)"]


def test_press_deeper_than_ball_and_unknown_session(make_recordings) -> None:
    root, _ = make_recordings()

    def edit(d):
        d["entries"][3]["labels"]["press_depth_mm"] = 3.5
        d["entries"][0]["session"] = "s9"

    _edit(root, edit)
    probs = _problems(root)
    assert "st-1: unknown session 's9'" in probs
    assert any("press depth 3.5 mm not below the ball radius 3.0 mm" in p for p in probs)


def test_every_problem_is_listed_and_cli_exits_1(make_recordings) -> None:
    root, _ = make_recordings()
    (root / "static.png").unlink()
    _edit(root, lambda d: d["entries"][2]["labels"].update(direction=3))
    assert len(_problems(root)) == 2
    res = CliRunner().invoke(app, ["check", str(root)])
    assert res.exit_code == 1
    assert "static.png: file not found" in res.output and "non-slip" in res.output
    assert "2 problem(s)" in res.output


def test_broken_manifest_is_a_problem_not_a_traceback(tmp_path) -> None:
    (tmp_path / MANIFEST_NAME).write_text("[1, 2")
    res = CliRunner().invoke(app, ["check", str(tmp_path)])
    assert res.exit_code == 1 and "invalid JSON" in res.output
    assert "Traceback" not in res.output


@pytest.mark.parametrize("deep", [False, True])
def test_deep_counts_video_frames(make_recordings, deep: bool) -> None:
    root, _ = make_recordings()
    _edit(root, lambda d: d["entries"][1]["source"].pop("stop"))
    rep = check_folder(root, deep=deep)
    assert rep.ok and rep.n_frames == 1 + 12 + 8 + 1
