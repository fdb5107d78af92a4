"""Hostile input, one class per test: each bad input is one line naming the file, exit 1 or 2,
no traceback, nothing lost (the numbered defects of the hardening review, in order)."""

from __future__ import annotations

import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pytest

from tests.fixtures.cli import clean, run
from tests.fixtures.data import ROOT
from vtsbench.errors import VtsError


def _edit_info(ds: Path, old: str, new: str) -> None:
    p = ds / "meta" / "info.json"
    text = p.read_text()
    assert old in text
    p.write_text(text.replace(old, new, 1))


# -- 1: info.json is checked, and the loader refuses metadata that contradicts the arrays ---------


@pytest.mark.parametrize("old, new", [('"depth_scale_mm": 0.001', '"depth_scale_mm": 0.101'),
                                      ('"frames_per_sequence": 8', '"frames_per_sequence": 9'),
                                      ('"resolution": [\n  96,', '"resolution": [\n  95,')])
def test_changed_info_json_fails_verify_and_load(ds: Path, old: str, new: str) -> None:
    import vtsbench

    _edit_info(ds, old, new)
    out = clean(run("verify", ds), 1, "meta/info.json")
    assert "info_sha256 mismatch" in out
    with pytest.raises(VtsError, match="info_sha256"):
        vtsbench.load(ds)


def test_every_flipped_bit_of_info_json_is_caught(ds: Path) -> None:
    from vtsbench.dataset.format.info import load_info

    p = ds / "meta" / "info.json"
    orig = p.read_bytes()
    rng = random.Random(0)
    for _ in range(300):
        b = bytearray(orig)
        b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
        p.write_bytes(bytes(b))
        with pytest.raises(VtsError):
            load_info(ds)
    p.write_bytes(orig)
    load_info(ds)


def test_metadata_contradicting_arrays_refused_by_the_loader(ds: Path) -> None:
    """Even with a recomputed info_sha256, a depth scale the arrays do not have is refused."""
    import vtsbench
    from vtsbench.dataset.format.info import DatasetInfo, load_info

    info = load_info(ds)
    doc = info.to_dict()
    doc["depth_scale_mm"] = 0.002
    (ds / "meta" / "info.json").write_text(DatasetInfo.from_dict(doc).to_json())
    with pytest.raises(VtsError, match="depth scale"):
        vtsbench.load(ds).static[0]


def test_format_1_0_info_without_its_hash_still_loads(ds: Path) -> None:
    """A genuine 1.0 dataset: its depth arrays carry the `scale` attribute 1.0 wrote."""
    from tests.fixtures.damage import depth_attrs_to_1_0
    from vtsbench.dataset.format.info import load_info

    depth_attrs_to_1_0(ds)
    info = load_info(ds)
    info.format_version = "1.0"
    (ds / "meta" / "info.json").write_text(info.to_json())
    assert "info_sha256" not in (ds / "meta" / "info.json").read_text()
    assert load_info(ds).format_version == "1.0"
    res = run("verify", ds, "--quick")
    assert res.exit_code == 0 and "carries no info_sha256" in res.output, res.output


# -- 2: repeated column names ------------------------------------------------------------------


@pytest.mark.parametrize("header", ["sample_id,task,pred,pred", "sample_id,sample_id,task,pred",
                                    "sample_id,task,pred,PRED"])
def test_submission_with_a_repeated_column_is_refused(ds: Path, tmp_path: Path,
                                                      header: str) -> None:
    sub = tmp_path / "s.csv"
    sub.write_text(header + "\nx,state,slip,slip\n")
    (tmp_path / "s.meta.json").write_text("{}")
    clean(run("eval", sub, "--dataset", ds, "--split", "seen"), 2, "s.csv", "more than once")


def test_motion_log_and_circles_with_a_repeated_column(tmp_path: Path) -> None:
    from vtsbench.recordings.importer import read_circles
    from vtsbench.recordings.motionlog import read_motion_log

    log = tmp_path / "log.csv"
    log.write_text("t_s,x_mm,y_mm,z_mm,x_mm\n0,0,0,0,1\n1,0,0,0,1\n")
    with pytest.raises(VtsError, match="repeats"):
        read_motion_log(log)
    circles = tmp_path / "c.csv"
    circles.write_text("file,x,y,r,x\na.png,1,2,3,4\n")
    with pytest.raises(VtsError, match="more than once"):
        read_circles(circles)


# -- 3: calibration coefficients ---------------------------------------------------------------


def test_calibration_with_nan_coefficients_is_refused(rec: Path, tmp_path: Path) -> None:
    from safetensors.numpy import load_file, save_file

    from vtsbench.depth.calibration import load_calibration

    path = rec / "calibration.safetensors"
    with open(path, "rb") as fh:
        n = int.from_bytes(fh.read(8), "little")
        meta = json.loads(fh.read(n))["__metadata__"]
    tensors = load_file(path)
    name = next(k for k, v in tensors.items() if v.dtype.kind == "f" and k != "zero_map")
    tensors[name] = tensors[name].copy()
    tensors[name].flat[0] = np.nan
    save_file(tensors, path, metadata=meta)
    with pytest.raises(VtsError, match="NaN"):
        load_calibration(path)
    clean(run("build", rec, tmp_path / "out", "--quiet"), 2, "calibration.safetensors", "NaN")
    assert not (tmp_path / "out").exists()


# -- 4: concurrent builds ----------------------------------------------------------------------


def test_a_build_whose_output_lock_is_held_is_refused(rec: Path, tmp_path: Path) -> None:
    import fcntl

    from vtsbench.dataset.build.staging import lock_path

    out = tmp_path / "out"
    with open(lock_path(out), "a+b") as fh:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        clean(run("build", rec, out, "--quiet"), 2, "another build")
    assert not out.exists()


def test_existence_is_checked_again_under_the_lock(rec: Path, tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """A dataset finished by another build between the first check and the lock is kept."""
    from vtsbench.dataset.build import pipeline as b

    out = tmp_path / "out"
    real = b.locked_stage

    def finished_meanwhile(o: Path):
        (o / "meta").mkdir(parents=True)
        (o / "meta" / "info.json").write_text("{}")
        return real(o)

    monkeypatch.setattr(b, "locked_stage", finished_meanwhile)
    with pytest.raises(VtsError, match="already exists"):
        b.build(rec, out, b.BuildOptions(progress=False))
    assert (out / "meta" / "info.json").read_text() == "{}"


# -- 5: outputs never replace a folder vtsbench did not write -------------------------------------


def test_simulate_and_collect_overwrite_keep_a_foreign_folder(tmp_path: Path) -> None:
    out = tmp_path / "paper"
    out.mkdir()
    (out / "main.tex").write_text("my thesis")
    clean(run("simulate", out, "--overwrite", "--static", 1, "--sequences", 0, "--presses", 0,
              "--size", "96x128", "--quiet"), 2, "paper", "not written by vtsbench")
    video = tmp_path / "v.avi"
    from tests.fixtures.data import write_video

    write_video(video, 20)
    clean(run("collect", out, "--source", video, "--overwrite", "--quiet"), 2, "paper",
          "not written by vtsbench")
    assert (out / "main.tex").read_text() == "my thesis"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["paper", "v.avi"]


def test_simulate_overwrite_replaces_its_own_folder(tmp_path: Path) -> None:
    out = tmp_path / "sim"
    args = ("simulate", out, "--static", 1, "--sequences", 0, "--presses", 0, "--size", "96x128",
            "--quiet")
    assert run(*args).exit_code == 0
    assert run(*args, "--overwrite").exit_code == 0


def test_depth_refuses_two_images_of_one_stem(rec: Path, tmp_path: Path) -> None:
    import cv2

    imgs = tmp_path / "imgs"
    imgs.mkdir()
    frame = next((rec / "static").glob("*.png"))
    shutil.copy(frame, imgs / "a.png")
    cv2.imwrite(str(imgs / "a.jpg"), cv2.imread(str(frame)))
    clean(run("depth", imgs, "--calibration", rec / "calibration.safetensors", "--out",
              tmp_path / "d"), 2, "a.jpg", "a.png")
    assert not (tmp_path / "d").exists()


def test_build_overwrite_leaves_a_foreign_old_folder(rec: Path, tmp_path: Path) -> None:
    out = tmp_path / "ds"
    theirs = tmp_path / ".ds.old"
    theirs.mkdir()
    (theirs / "keep.txt").write_text("mine")
    assert run("build", rec, out, "--quiet").exit_code == 0
    assert run("build", rec, out, "--quiet", "--overwrite").exit_code == 0
    assert (theirs / "keep.txt").read_text() == "mine"
    assert run("verify", out, "--quick").exit_code == 0


# -- 6: frames decoded by OpenCV only ---------------------------------------------------------


def test_own_png_decoder_is_gone() -> None:
    with pytest.raises(ImportError):
        __import__("vtsbench.recordings.png")


def _chunk(kind: bytes, data: bytes) -> bytes:
    return (len(data).to_bytes(4, "big") + kind + data
            + zlib.crc32(kind + data).to_bytes(4, "big"))


def test_png_declaring_40000x40000_is_refused_quickly(tmp_path: Path) -> None:
    from vtsbench.recordings.media import read_image

    ihdr = (40000).to_bytes(4, "big") * 2 + bytes([8, 2, 0, 0, 0])
    body = zlib.compress(b"\0" * 1000)
    path = tmp_path / "huge.png"
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", body)
                     + _chunk(b"IEND", b""))
    t0 = time.perf_counter()
    with pytest.raises(VtsError, match=r"huge\.png"):
        read_image(path)
    assert time.perf_counter() - t0 < 5


def test_png_with_a_bad_idat_crc_is_refused(tmp_path: Path) -> None:
    import cv2

    from vtsbench.recordings.media import read_image

    _, buf = cv2.imencode(".png", np.full((20, 30, 3), 7, np.uint8))
    data = bytearray(buf.tobytes())
    i = data.find(b"IDAT")
    n = int.from_bytes(data[i - 4:i], "big")
    data[i + 4 + n] ^= 0xFF  # the CRC's first byte
    path = tmp_path / "crc.png"
    path.write_bytes(bytes(data))
    with pytest.raises(VtsError, match="cannot decode"):
        read_image(path)


def test_check_says_what_it_does_with_a_16_bit_frame(make_recordings) -> None:
    import cv2

    root, _ = make_recordings()
    img = cv2.imread(str(root / "static.png"))
    cv2.imwrite(str(root / "static.png"), img.astype(np.uint16) * 257)
    res = run("check", root)
    assert res.exit_code == 0, res.output
    assert "16-bit samples: decoded to 8 bits" in res.output and "static.png" in res.output
    from vtsbench.recordings.media import read_image

    np.testing.assert_array_equal(read_image(root / "static.png"), img[..., ::-1])


def test_an_exif_oriented_frame_is_turned_and_said(tmp_path: Path) -> None:
    """OpenCV applies the EXIF orientation (its documented IMREAD_COLOR behaviour); check's
    note says so, with the stored and the read size."""
    from PIL import Image

    from vtsbench.recordings.media import frame_notes, read_image

    img = np.zeros((20, 40, 3), np.uint8)
    img[:5] = 255  # a white band along the top, so the turn is visible
    exif = Image.Exif()
    exif[0x0112] = 6  # rotate 90 degrees clockwise to display
    Image.fromarray(img).save(tmp_path / "o.jpg", exif=exif.tobytes(), quality=95)
    notes = frame_notes(tmp_path / "o.jpg")
    assert len(notes) == 1 and "EXIF orientation" in notes[0] and "40x20 stored" in notes[0]
    out = read_image(tmp_path / "o.jpg")
    assert out.shape == (40, 20, 3)
    assert out[:, -5:].mean() > 200 and out[:, :10].mean() < 30  # the top band is now right
    Image.fromarray(img).save(tmp_path / "plain.jpg", quality=95)
    assert frame_notes(tmp_path / "plain.jpg") == []


# -- 7: NaN and infinity --------------------------------------------------------------------------


@pytest.mark.parametrize("args", [
    ("manifest", "{d}", "--pattern", "{{object}}.png", "--mm-per-px", "nan"),
    ("manifest", "{d}", "--pattern", "{{object}}.png", "--fps", "inf"),
    ("simulate", "{d}/s", "--mm-per-px", "nan"),
    ("collect", "{d}/c", "--source", "0", "--mount-rotation", "nan"),
    ("calibrate", "{d}", "--out", "{d}/c.safetensors", "--mm-per-px", "-inf"),
    ("build", "{d}", "{d}/o", "--shard-mb", "nan"),
])
def test_nan_and_infinity_options_are_refused(tmp_path: Path, args: tuple[str, ...]) -> None:
    res = run(*(a.format(d=tmp_path) for a in args))
    assert res.exit_code == 2 and "Invalid value" in res.output, res.output
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_bad_option_from_the_console_is_one_line(tmp_path: Path) -> None:
    """The console entry point prints a usage error as one line (not click's box), exit 2."""
    res = subprocess.run([sys.executable, "-m", "vtsbench", "manifest", str(tmp_path),
                          "--pattern", "{object}.png", "--mm-per-px", "nan"],
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 2 and res.stdout == "", res
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "--mm-per-px" in lines[0] and "finite" in lines[0], lines
    ok = subprocess.run([sys.executable, "-m", "vtsbench", "--help"], capture_output=True,
                        text=True, timeout=60)
    assert ok.returncode == 0 and "build" in ok.stdout
    bad = subprocess.run([sys.executable, "-m", "vtsbench", "verify", str(tmp_path / "none")],
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode in (1, 2) and "Traceback" not in bad.stderr


@pytest.mark.parametrize("literal", ["NaN", "Infinity", "-Infinity", "1e999"])
def test_nan_in_a_manifest_is_refused(make_recordings, literal: str) -> None:
    root, _ = make_recordings()
    p = root / "recordings.json"
    doc = p.read_text()
    p.write_text(doc.replace('"ball_radius_mm": 3.0', f'"ball_radius_mm": {literal}', 1))
    out = clean(run("check", root), 1, "recordings.json")
    assert "1 problem" in out


# -- 8: hangs --------------------------------------------------------------------------------


def test_a_fifo_or_dev_zero_named_like_a_frame_is_refused(make_recordings) -> None:
    root, _ = make_recordings()
    (root / "static.png").unlink()
    os.mkfifo(root / "static.png")
    for cmd in (["check", str(root)], ["preview", str(root), "--out", str(root / "p.png")]):
        res = subprocess.run([sys.executable, "-m", "vtsbench", *cmd], capture_output=True,
                             text=True, timeout=60)
        assert res.returncode in (1, 2) and "not a regular file" in res.stdout + res.stderr
    (root / "static.png").unlink()
    (root / "static.png").symlink_to("/dev/zero")
    clean(run("check", root), 1, "static.png", "not a regular file")


def test_a_flow_checkpoint_whose_tree_loops_is_refused(tmp_path: Path) -> None:
    from vtsbench.recipes_builtin.flow import _Tree

    left = np.array([1, 0, -1], np.int64)  # node 1 goes back to node 0
    right = np.array([2, 2, -1], np.int64)
    with pytest.raises(ValueError, match="loop"):
        _Tree(left, right, np.zeros(3, np.int64), np.zeros(3), np.zeros(3, np.int64))


def test_a_shard_linked_to_dev_zero_is_refused_by_the_loader(ds: Path) -> None:
    import vtsbench

    shard = ds / "data" / "static.zarr" / "rgb" / "c" / "0" / "0" / "0" / "0"
    shard.unlink()
    shard.symlink_to("/dev/zero")
    with pytest.raises(VtsError, match="not a regular file"):
        vtsbench.load(ds).static[0]
    out = clean(run("verify", ds), 1, "c/0/0/0/0")
    assert "missing" in out


# -- 9: kill -9 of a build leaves no workers ---------------------------------------------------


def _children(pid: int) -> list[int]:
    out = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        text = (task / "children").read_text().split()
        out += [int(x) for x in text]
    return out


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="needs /proc")
def test_kill_9_of_a_build_leaves_no_worker(rec: Path, tmp_path: Path) -> None:
    err = tmp_path / "stderr.txt"
    with open(err, "wb") as fh:
        proc = subprocess.Popen([sys.executable, "-m", "vtsbench", "build", str(rec),
                                 str(tmp_path / "o"), "--workers", "2", "--quiet"],
                                stdout=subprocess.DEVNULL, stderr=fh)
    workers: list[int] = []
    deadline = time.time() + 60
    while time.time() < deadline and len(workers) < 2 and proc.poll() is None:
        time.sleep(0.1)
        workers = [c for c in _children(proc.pid)
                   if b"resource_tracker" not in Path(f"/proc/{c}/cmdline").read_bytes()]
    assert len(workers) >= 2, (f"the build started no workers (exit {proc.poll()}): "
                               f"{err.read_text(errors='replace')[-2000:]}")
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    deadline = time.time() + 15
    while time.time() < deadline and any(Path(f"/proc/{w}").exists() for w in workers):
        time.sleep(0.2)
    alive = [w for w in workers if Path(f"/proc/{w}").exists()
             and Path(f"/proc/{w}/stat").read_text().split()[2] != "Z"]
    assert not alive


# -- 10: zarr.json and shards ---------------------------------------------------------------


def test_every_flipped_byte_of_zarr_json_is_a_verify_problem(ds: Path) -> None:
    from vtsbench.dataset.tools.verify import verify

    p = ds / "data" / "slip.zarr" / "zarr.json"
    orig = p.read_bytes()
    for i in range(0, len(orig), max(1, len(orig) // 60)):
        b = bytearray(orig)
        b[i] ^= 1
        p.write_bytes(bytes(b))
        report = verify(ds, decode=False)
        assert any("zarr.json" in x for x in report.problems), i
    p.write_bytes(orig)


def test_flipped_shard_byte_names_file_and_sample(ds: Path) -> None:
    import vtsbench

    shard = ds / "data" / "static.zarr" / "rgb" / "c" / "0" / "0" / "0" / "0"
    b = bytearray(shard.read_bytes())
    b[100] ^= 0x5A
    shard.write_bytes(bytes(b))
    with pytest.raises(VtsError, match=r"rgb/c/0/0/0/0: sample \S+ \(row 0\) does not decode"):
        vtsbench.load(ds).static[0]


# -- 11: rich markup in paths ------------------------------------------------------------------


@pytest.mark.parametrize("name", ["[/x]", "[bold]rec"])
def test_markup_in_paths_is_printed_as_is(make_recordings, tmp_path: Path, name: str) -> None:
    root, _ = make_recordings()
    odd = tmp_path / name
    shutil.move(root, odd)
    (odd / "recordings.json").write_text("{")
    res = run("check", odd)
    assert res.exit_code == 1 and f"{name}/recordings.json" in res.output, res.output


# -- 12: tracebacks become one-line errors ------------------------------------------------------


def test_deep_json_huge_numbers_and_float_indices(make_recordings) -> None:
    root, _ = make_recordings()
    p = root / "recordings.json"
    orig = p.read_text()
    for bad in ("[" * 100_000 + "]" * 100_000, orig.replace('"name": "tiny"',
                '"name": "tiny", "x": ' + "9" * 5000, 1)):
        p.write_text(bad)
        clean(run("check", root), 1, "recordings.json")
    p.write_text(orig.replace('"frame": 0', '"frame": 0.0').replace('"start": 0', '"start": 0.0'))
    assert "0.0" in p.read_text()
    clean(run("check", root), 1, "recordings.json", "integer")


def test_csv_field_over_128_kib_and_truncated_index(ds: Path, tmp_path: Path) -> None:
    sub = tmp_path / "s.csv"
    sub.write_text("sample_id,task,pred\nx,state," + "y" * 200_000 + "\n")
    (tmp_path / "s.meta.json").write_text("{}")
    clean(run("eval", sub, "--dataset", ds, "--split", "seen"), 2, "s.csv", "field limit")
    idx = ds / "index" / "slip.parquet"
    idx.write_bytes(idx.read_bytes()[:200])
    clean(run("info", ds), 2, "slip.parquet")


def test_bad_outputs_and_names(rec: Path, tmp_path: Path) -> None:
    afile = tmp_path / "afile"
    afile.write_text("x")
    clean(run("preview", rec, "--out", tmp_path), 2, "is a folder")
    clean(run("preview", rec, "--out", tmp_path / ("x" * 300 + ".png")), 2, "too long")
    clean(run("build", rec, afile, "--quiet"), 2, "afile")
    clean(run("depth", rec / "static", "--calibration", rec / "calibration.safetensors",
              "--out", afile), 2, "afile")
    assert afile.read_text() == "x"


def test_bad_manifest_options(rec: Path, tmp_path: Path) -> None:
    args = ("manifest", rec / "static", "--pattern", "{object}.png", "--out", tmp_path / "m")
    clean(run(*args, "--kind", "press", "--ball-radius-mm", "-1"), 2, "recordings.json",
          "ball_radius_mm")
    clean(run(*args, "--session", "../x"), 2, "session")
    clean(run(*args, "--kind", "bogus"), 2, "bogus")


def test_calibrate_background_size_and_absurd_bins(rec: Path, tmp_path: Path) -> None:
    import cv2

    bg = tmp_path / "bg.png"
    cv2.imwrite(str(bg), np.zeros((10, 12, 3), np.uint8))
    out = tmp_path / "c.safetensors"
    clean(run("calibrate", rec, "--out", out, "--background", bg), 2, "bg.png", "10x12")
    clean(run("calibrate", rec, "--out", out, "--method", "lut", "--bins", 10**8), 2, "--bins")
    assert not out.exists()


def test_depth_on_mixed_frame_sizes(rec: Path, tmp_path: Path) -> None:
    import cv2

    imgs = tmp_path / "imgs"
    imgs.mkdir()
    frame = next((rec / "static").glob("*.png"))
    shutil.copy(frame, imgs / "a.png")
    cv2.imwrite(str(imgs / "b.png"), cv2.imread(str(frame))[:50])
    clean(run("depth", imgs, "--calibration", rec / "calibration.safetensors", "--out",
              tmp_path / "d"), 2, "b.png", "50x128")


def test_missing_torch_is_one_line(ds: Path, tmp_path: Path) -> None:
    code = ("import sys; sys.modules['torch'] = None; from vtsbench.cli import main; "
            "sys.argv = ['vtsbench', 'train', 'resnet', '--dataset', sys.argv[1], '--split', "
            "'static_sessions', '--out', sys.argv[2]]; main()")
    res = subprocess.run([sys.executable, "-c", code, str(ds), str(tmp_path / "r")],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
    assert "torch" in res.stderr and len(res.stderr.strip().splitlines()) == 1
    code = ("import sys; sys.modules['torch'] = None; import vtsbench; "
            "vtsbench.load(sys.argv[1]).split('seen', 'train').to_torch()")
    res = subprocess.run([sys.executable, "-c", code, str(ds)], capture_output=True, text=True,
                         timeout=120)
    assert "vtsbench[torch]" in res.stderr


def test_bad_checkpoint_and_config(ds: Path, tmp_path: Path) -> None:
    ckpt = tmp_path / "c.safetensors"
    ckpt.write_bytes(b"garbage")
    clean(run("predict", "flow", ckpt, "--dataset", ds, "--split", "seen", "--out",
              tmp_path / "p.csv"), 2, "c.safetensors")
    head = json.dumps({"__metadata__": {"config": "[" * 50_000}}).encode()
    ckpt.write_bytes(len(head).to_bytes(8, "little") + head)
    clean(run("predict", "flow", ckpt, "--dataset", ds, "--split", "seen", "--out",
              tmp_path / "p.csv"), 2, "c.safetensors")
    cfg = tmp_path / "cfg.json"
    cfg.write_text('{"max_depth": "deep"}')
    clean(run("train", "flow", "--dataset", ds, "--split", "seen", "--out", tmp_path / "r",
              "--config", cfg), 2, "cfg.json", "max_depth")


# -- 13: leaderboard ----------------------------------------------------------------------------


def test_leaderboard_split_with_a_path_is_refused(tmp_path: Path) -> None:
    sub = tmp_path / "s.csv"
    sub.write_text("sample_id,task,pred\n")
    clean(run("leaderboard", "add", sub, "--dataset", tmp_path, "--split", "../../x", "--root",
              tmp_path / "lb"), 2, "split name")
    assert not (tmp_path / "lb").exists()


def test_method_names_cannot_inject_markdown() -> None:
    from vtsbench.evaluation.leaderboard import md_cell

    cell = md_cell("evil\n\n# Heading | x [a](http://e) <img src=x>")
    assert "\n" not in cell and "\\|" in cell and "]\\(" in cell and "<" not in cell
    assert md_cell("[9.50, 14.77]") == "[9.50, 14.77]"


# -- 14: simulate at a small size -------------------------------------------------------------


def test_press_placement_at_96x128_for_many_seeds() -> None:
    from vtsbench.sim.plan import press_scene

    for seed in range(400):
        for size in ((96, 128), (64, 64), (97, 96)):
            scene = press_scene(np.random.default_rng(seed), size, 0.03)
            ((cx, cy),) = scene.centers_px
            assert 0 <= cx <= size[1] - 1 and 0 <= cy <= size[0] - 1


def test_simulate_96x128_seed_1(tmp_path: Path) -> None:
    res = run("simulate", tmp_path / "s", "--seed", 1, "--static", 1, "--sequences", 0,
              "--presses", 6, "--size", "96x128", "--quiet")
    assert res.exit_code == 0, res.output


# -- 15: packaging ------------------------------------------------------------------------------


def test_the_wheel_holds_vtsbench_only_and_declares_its_imports() -> None:
    import tomllib
    from setuptools import find_packages

    root = ROOT
    doc = tomllib.loads((root / "pyproject.toml").read_text())
    include = doc["tool"]["setuptools"]["packages"]["find"]["include"]
    top = {p.split(".")[0] for p in find_packages(str(root), include=include)}
    assert top == {"vtsbench"}
    deps = " ".join(doc["project"]["dependencies"])
    assert "google-crc32c" in deps and "isal" not in deps
    for ep in doc["project"]["entry-points"]["vtsbench.recipes"].values():
        assert ep.startswith("vtsbench.recipes.builtin.")
