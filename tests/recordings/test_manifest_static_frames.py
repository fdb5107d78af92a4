"""`vtsbench manifest --kind static --stride N` on videos: one static entry every N frames."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
from typer.testing import CliRunner

from vtsbench.cli import app


def _video(path: Path, n: int) -> None:
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (32, 24))
    for k in range(n):
        w.write(np.full((24, 32, 3), 10 * k, np.uint8))
    w.release()


def test_static_frames_every_stride(tmp_path: Path) -> None:
    vids = tmp_path / "v"
    vids.mkdir()
    _video(vids / "apple_0.avi", 10)
    _video(vids / "egg_1.avi", 4)
    res = CliRunner().invoke(app, ["manifest", str(vids), "--pattern", "{object}_{session:d}.avi",
                                   "--kind", "static", "--stride", "3", "--out",
                                   str(tmp_path / "rec")])
    assert res.exit_code == 0, res.output
    doc = json.loads((tmp_path / "rec" / "recordings.json").read_text())
    got = {e["id"]: (e["kind"], e["object"], e["session"], e["source"]["frame"])
           for e in doc["entries"]}
    want = {f"apple_0-f{f:05d}": ("static", "apple", "0", f) for f in (0, 3, 6, 9)}
    want.update({f"egg_1-f{f:05d}": ("static", "egg", "1", f) for f in (0, 3)})
    assert got == want
    res = CliRunner().invoke(app, ["check", str(tmp_path / "rec")])
    assert res.exit_code == 0, res.output
    # without --stride: the first frame only, as before
    res = CliRunner().invoke(app, ["manifest", str(vids), "--pattern", "{object}_{session:d}.avi",
                                   "--kind", "static", "--out", str(tmp_path / "rec2")])
    doc = json.loads((tmp_path / "rec2" / "recordings.json").read_text())
    assert sorted(e["id"] for e in doc["entries"]) == ["apple_0", "egg_1"]
