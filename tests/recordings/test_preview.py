"""`vtsbench preview` writes a contact sheet, with true depth beside frames that have it."""

import numpy as np
from typer.testing import CliRunner

from vtsbench.cli import app
from vtsbench.recordings.manifest import load_manifest
from vtsbench.recordings.preview import pick_entries
from vtsbench.recordings.truth import Truth, write_truth


def test_pick_spreads_over_kinds(make_recordings) -> None:
    _root, m = make_recordings()
    picked = pick_entries(m, 3, seed=1)
    assert len({(e.kind, e.labels.state) for e in picked}) == 3
    assert pick_entries(m, 3, seed=1) == picked
    assert len(pick_entries(m, 99)) == len(m.entries)


def test_preview_png_with_truth(make_recordings, tmp_path) -> None:
    import json

    root, _ = make_recordings()
    depth = np.zeros((1, 48, 64), np.float32)
    depth[0, 10:20, 10:20] = 0.5
    (root / "truth").mkdir()
    write_truth(root / "truth" / "st-1.npz",
                Truth(depth, np.zeros((1, 48, 64, 2), np.float32), depth > 0, np.zeros((1, 2))))
    doc = json.loads((root / "recordings.json").read_text())
    doc["entries"][0]["truth"] = "truth/st-1.npz"
    (root / "recordings.json").write_text(json.dumps(doc))
    load_manifest(root)
    out = tmp_path / "sheet.png"
    res = CliRunner().invoke(app, ["preview", str(root), "--out", str(out), "-n", "4"])
    assert res.exit_code == 0, res.output
    import cv2

    img = cv2.imread(str(out))
    assert img is not None and img.shape[0] > 100 and img.shape[1] > 400
    assert not list(tmp_path.glob(".*tmp*"))


def test_preview_of_missing_folder_is_one_line(tmp_path) -> None:
    args = ["preview", str(tmp_path / "x"), "--out", str(tmp_path / "p.png")]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 2 and "not a folder" in res.output and "Traceback" not in res.output
