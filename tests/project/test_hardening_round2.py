"""Hostile input and faults, second round: a full disk names the file, every refusal gives the
right reason, `check --deep` sees every frame of a sequence folder, and small holes closed
(eval's missing ids, empty split parts, two file columns, Hub repository ids, contact_px)."""

from __future__ import annotations

import csv
import errno
import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.fixtures.cli import clean, run
from vtsbench.errors import VtsError


def _submission(ds: Path, folder: Path, split: str = "unseen_objects", part: str = "test",
                prefix: str = "") -> Path:
    """Predictions equal to the truth (ids with `prefix` prepended), with their metadata."""
    from vtsbench.dataset.format.info import load_info
    from vtsbench.evaluation.submission import load_truth

    t, info = load_truth(ds, split, part), load_info(ds / "meta" / "info.json")
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "sub.csv"
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["sample_id", "task", "pred"])
        for i, s in enumerate(t.ids):
            w.writerow([prefix + s, "state", int(t.labels["state"][i])])
            if t.labels["direction"][i] >= 0:
                w.writerow([prefix + s, "direction", int(t.labels["direction"][i])])
    (folder / "sub.meta.json").write_text(json.dumps({
        "method": "toy", "recipe": "toy", "seeds": [0], "dataset_version": info.dataset_version,
        "dataset_sha256": info.dataset_sha256}))
    return path


# -- 11: a full disk names the file being written ---------------------------------------------


class _FullDisk:
    """A file whose writes fail as on a full disk: ENOSPC, naming no file."""

    def __init__(self, fh) -> None:
        self._fh = fh

    def __enter__(self) -> _FullDisk:
        return self

    def __exit__(self, *exc: object) -> None:
        self._fh.close()

    def write(self, data: object) -> int:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    def writelines(self, parts: object) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def _disk_full(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every file written through vtsbench.atomic fails as on a full disk."""
    import builtins

    import vtsbench.atomic as atomic

    def full_open(file, mode="r", *a, **kw):
        fh = builtins.open(file, mode, *a, **kw)  # noqa: SIM115 - closed by _FullDisk
        return _FullDisk(fh) if any(m in mode for m in "wxa") else fh

    monkeypatch.setattr(atomic, "open", full_open, raising=False)


COMMANDS = {
    "simulate": lambda rec, ds, sub, o: ("simulate", o, "--static", 2, "--sequences", 0,
                                         "--presses", 0, "--size", "48x64", "--quiet"),
    "build": lambda rec, ds, sub, o: ("build", rec, o, "--quiet"),
    "calibrate": lambda rec, ds, sub, o: ("calibrate", rec, "--out", o / "c.safetensors",
                                          "--method", "lut"),
    "depth": lambda rec, ds, sub, o: ("depth", rec / "static", "--calibration",
                                      rec / "calibration.safetensors", "--out", o),
    "preview": lambda rec, ds, sub, o: ("preview", rec, "--out", o / "p.png", "-n", 2),
    "eval": lambda rec, ds, sub, o: ("eval", sub, "--dataset", ds, "--split",
                                     "unseen_objects", "--out", o, "--no-figures"),
    "leaderboard add": lambda rec, ds, sub, o: ("leaderboard", "add", sub, "--dataset", ds,
                                                "--split", "unseen_objects", "--root", o),
}


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_a_full_disk_names_the_file(command: str, rec: Path, ds: Path, tmp_path: Path,
                                    monkeypatch: pytest.MonkeyPatch) -> None:
    sub = _submission(ds, tmp_path / "subs")
    out = tmp_path / "the_output"
    args = COMMANDS[command](rec, ds, sub, out)
    _disk_full(monkeypatch)
    msg = clean(run(*args), 2, "the_output", "cannot write (No space left on device)")
    assert msg.count("error:") == 1, msg
    assert msg.strip().splitlines()[-1].startswith(f"error: {tmp_path}"), msg


def test_a_library_write_on_a_full_disk_names_the_output(rec: Path, tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """An OSError naming no file, from outside vtsbench's writers: the command's output."""
    import vtsbench.figures as figures

    def full(*a, **kw):
        raise OSError(errno.EFBIG, os.strerror(errno.EFBIG))

    monkeypatch.setattr(figures, "png_bytes", full)
    out = tmp_path / "sheet.png"
    clean(run("preview", rec, "--out", out, "-n", 2), 2,
          f"error: {out}: cannot write (File too large)")


def test_a_file_size_limit_names_the_file(tmp_path: Path) -> None:
    """A real full disk: writes past RLIMIT_FSIZE fail with EFBIG (SIGXFSZ ignored)."""
    import resource

    def limit() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096))

    out = tmp_path / "simdir"
    res = subprocess.run([sys.executable, "-m", "vtsbench", "simulate", str(out), "--static",
                          "2", "--sequences", "0", "--presses", "0", "--size", "48x64",
                          "--quiet"], capture_output=True, text=True, timeout=120,
                         preexec_fn=limit)
    assert res.returncode == 2, res.stderr
    err = res.stderr.strip()
    assert "\n" not in err and err.startswith(f"error: {tmp_path}"), err
    assert "simdir" in err and "cannot write (File too large)" in err, err
    assert not out.exists()


# -- 12: the right reason ---------------------------------------------------------------------


@pytest.fixture
def odd_files(tmp_path: Path) -> dict[str, tuple[Path, str]]:
    """A folder, a FIFO, /dev/zero and a missing file, with the reason each must get."""
    (tmp_path / "afolder").mkdir()
    os.mkfifo(tmp_path / "afifo")
    return {"folder": (tmp_path / "afolder", "is a folder"),
            "fifo": (tmp_path / "afifo", "not a regular file"),
            "device": (Path("/dev/zero"), "not a regular file"),
            "missing": (tmp_path / "nothing.json", "not found")}


@pytest.mark.parametrize("kind", ["folder", "fifo", "device", "missing"])
def test_split_file_and_object_list_reasons(odd_files, kind: str) -> None:
    from vtsbench.dataset.splits.given import read_object_list, read_split_file

    path, reason = odd_files[kind]
    for read in (read_object_list, read_split_file):
        with pytest.raises(VtsError, match=reason) as e:
            read(path)
        assert str(path) in str(e.value)


@pytest.mark.parametrize("option", ["--holdout-objects", "--split-file"])
def test_build_says_a_split_file_is_a_folder(rec: Path, tmp_path: Path, option: str) -> None:
    (tmp_path / "given").mkdir()
    clean(run("build", rec, tmp_path / "out", option, tmp_path / "given", "--quiet"), 2,
          f"{tmp_path / 'given'}: is a folder")


@pytest.mark.parametrize("kind", ["fifo", "folder"])
def test_a_fifo_or_folder_among_sequence_frames(make_recordings, kind: str) -> None:
    root, _ = make_recordings()
    frame = root / "seqdir" / "003.png"
    frame.unlink()
    os.mkfifo(frame) if kind == "fifo" else frame.mkdir()
    out = clean(run("check", root), 1, "seq-2", f"{frame}: ")
    assert "past the end" not in out
    assert ("is a folder" if kind == "folder" else "not a regular file") in out


def _truncated_png(path: Path) -> Path:
    """A PNG cut in its image data (libpng says "libpng error: ... incomplete")."""
    from vtsbench.recordings.media import write_png

    write_png(path, np.random.default_rng(0).integers(0, 256, (96, 128, 3), dtype=np.uint8))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    return path


@pytest.mark.parametrize("name", ["cut.png", "nomoov.mp4"])
def test_no_library_text_before_the_error(rec: Path, tmp_path: Path, name: str) -> None:
    """libpng's "libpng error" and FFmpeg's "moov atom not found" stay out of stderr."""
    bad = tmp_path / name
    if name.endswith(".png"):
        _truncated_png(bad)
    else:
        bad.write_bytes(b"\0\0\0\x20ftypisom\0\0\x02\0isomiso2avc1mp41" + b"\0" * 64)
    res = subprocess.run([sys.executable, "-m", "vtsbench", "depth", str(bad), "--calibration",
                          str(rec / "calibration.safetensors"), "--out", str(tmp_path / "d")],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 2
    assert res.stderr.count("\n") == 1 and res.stderr.startswith(f"error: {bad}: "), res.stderr


def test_check_prints_no_library_text(make_recordings) -> None:
    root, _ = make_recordings(96, 128)
    _truncated_png(root / "static.png")
    res = subprocess.run([sys.executable, "-m", "vtsbench", "check", str(root)],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 1 and "cannot decode image" in res.stdout, res.stdout
    assert "libpng" not in res.stdout
    assert all(ln.startswith("checking sources") for ln in res.stderr.splitlines()), res.stderr


def test_quiet_decoding_nests_and_restores() -> None:
    import cv2

    from vtsbench.recordings.quiet import quiet_decoding

    level = cv2.utils.logging.getLogLevel()
    with quiet_decoding():
        with quiet_decoding():
            assert cv2.utils.logging.getLogLevel() == cv2.utils.logging.LOG_LEVEL_SILENT
        assert cv2.utils.logging.getLogLevel() == cv2.utils.logging.LOG_LEVEL_SILENT
    assert cv2.utils.logging.getLogLevel() == level


def test_predict_into_a_folder_names_the_folder(ds: Path, tmp_path: Path) -> None:
    runs, folder = tmp_path / "runs", tmp_path / "afolder"
    folder.mkdir()
    res = run("train", "flow", "--dataset", ds, "--split", "unseen_objects", "--out", runs,
              "--quiet")
    assert res.exit_code == 0, res.output
    out = clean(run("predict", "flow", runs / "checkpoint.safetensors", "--dataset", ds,
                    "--split", "unseen_objects", "--out", folder), 2,
                f"error: {folder}: is a folder")
    assert ".tmp" not in out


# -- 13: check --deep reads every frame of a sequence folder ----------------------------------


def test_deep_check_sees_sizes_and_16_bit_frames_in_a_sequence(make_recordings) -> None:
    import cv2

    root, _ = make_recordings()
    img = cv2.imread(str(root / "seqdir" / "003.png"))
    cv2.imwrite(str(root / "seqdir" / "003.png"), cv2.resize(img, (32, 24)))
    cv2.imwrite(str(root / "seqdir" / "005.png"), img.astype(np.uint16) * 257)
    out = clean(run("check", root, "--deep"), 1, "seq-2", "48x64", "24x32", "003.png")
    assert "1 problem" in out
    assert f"{root / 'seqdir' / '005.png'}: 16-bit samples" in out
    from vtsbench.recordings.media import read_frames

    with pytest.raises(VtsError, match=r"frames of two sizes: 000.png is 48x64, 003.png is 24x32"):
        read_frames(root / "seqdir", 0, 8)  # what build says of the sequence


# -- 14: eval says which ids are missing even when no row names one ----------------------------


def test_eval_lists_missing_ids_when_no_row_matches(ds: Path, tmp_path: Path) -> None:
    from vtsbench.evaluation.submission import load_truth

    n = len(load_truth(ds, "unseen_objects", "test").ids)
    sub = _submission(ds, tmp_path, prefix="x")
    out = clean(run("eval", sub, "--dataset", ds, "--split", "unseen_objects"), 2, "sub.csv",
                "ids not in split", f"missing ids (0 of {n} test samples predicted): {n}")
    assert "2 problem(s)" in out
    shown = re.search(r"ids not in split [^:]+: \d+ \(first: ([^)]*)\)", out).group(1).split(", ")
    assert len(shown) == len(set(shown)), out  # a sample's state and direction rows: named once


# -- 15: an empty split part, two file columns, a Hub repository id ----------------------------


def test_a_split_file_with_an_empty_part_is_refused_at_build(rec: Path, built: Path,
                                                             tmp_path: Path) -> None:
    doc = json.loads((built / "meta" / "splits" / "unseen_objects.json").read_text())
    doc["name"] = "mine"
    doc["parts"]["val"] = []
    f = tmp_path / "mine.json"
    f.write_text(json.dumps(doc))
    out = tmp_path / "out"
    clean(run("build", rec, out, "--split-file", f, "--quiet"), 2, f"{f}: part 'val' lists "
          "no sample")
    assert not out.exists()


def test_a_labels_csv_with_two_file_columns_is_refused(tmp_path: Path) -> None:
    from vtsbench.recordings.labels_file import read_labels

    f = tmp_path / "labels.csv"
    f.write_text("path,file,state\na.png,b.png,static\n")
    with pytest.raises(VtsError, match="two file columns, path and file") as e:
        read_labels(f)
    assert str(f) in str(e.value)


@pytest.mark.parametrize("repo", ["../../evil", "a/b/c", "evil", "me/.x", "me/x-", "me/a..b",
                                  "me/a--b", "me/" + "x" * 97, "me/a b", "me/x.git"])
def test_push_checks_the_repository_id_first(tmp_path: Path, repo: str) -> None:
    """Before the dataset is even read: the folder here does not exist."""
    out = clean(run("push", tmp_path / "nothing", repo, "--dry-run"), 2, "repository id")
    assert "nothing" not in out


def test_push_accepts_hub_repository_ids() -> None:
    from vtsbench.dataset.tools.push import check_repo_id

    for repo in ("me/tactile", "my-lab/tactile_v1.2", "A/" + "x" * 96, "u/x"):
        assert check_repo_id(repo) == repo


# -- 7 (recordings side): contact_px outside the frame ----------------------------------------


def test_contact_px_outside_the_frame_fails_check_and_build(make_recordings,
                                                            tmp_path: Path) -> None:
    root, _ = make_recordings()
    p = root / "recordings.json"
    doc = json.loads(p.read_text())
    st = next(e for e in doc["entries"] if e["id"] == "st-1")
    st["labels"]["contact_px"] = [-500, 1e6]
    p.write_text(json.dumps(doc))
    clean(run("check", root), 1, "st-1", "contact_px [-500, 1e+06] outside the frame")
    clean(run("build", root, tmp_path / "out", "--no-depth", "--quiet"), 2,
          "bad recording st-1", "contact_px [-500, 1e+06] outside the frame")
    st["labels"]["contact_px"] = [64, 48]  # the far corner: inside
    p.write_text(json.dumps(doc))
    res = run("check", root)
    assert "contact_px" not in res.output, res.output
