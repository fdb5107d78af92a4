"""`vtsbench import-presses`: gs_sdk calibration folders and Taxim packs as recordings folders."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from tests.fixtures.data import real_dir
from vtsbench.cli import app
from vtsbench.errors import VtsError
from vtsbench.recordings.manifest import Circle, load_manifest
from vtsbench.recordings.media import read_image, write_png
from vtsbench.recordings.press_folders import import_presses, read_label

MM_PER_PX = 0.06


@pytest.fixture(scope="module")
def sim(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Ten simulated presses of a 3 mm ball under one background, with their exact circles."""
    from vtsbench.sim.simulate import simulate

    root = tmp_path_factory.mktemp("presses") / "sim"
    simulate(root, seed=23, n_static=0, n_sequences=0, n_presses=10, size=(120, 160),
             mm_per_px=MM_PER_PX, n_sessions=1, generator=1)
    return root


def gs_folder(sim: Path, dst: Path, *, labels: bool = True, skip_label: int | None = None
              ) -> Path:
    """The simulated presses laid out as gs_sdk's calibration scripts write them (with the
    labelling tool's `labeled.png` beside each labelled press)."""
    m = load_manifest(sim)
    dst.mkdir(parents=True)
    write_png(dst / "background.png", read_image(sim / m.sessions[0].background))
    rows = ["experiment_reldir,diameter(mm)"]
    for k, e in enumerate(e for e in m.entries if e.kind == "press"):
        rel = f"{2 * e.ball_radius_mm:.3f}mm/{k}"
        (dst / rel).mkdir(parents=True)
        frame = read_image(sim / e.source.path)
        write_png(dst / rel / "gelsight.png", frame)
        if labels and k != skip_label:
            np.savez(dst / rel / "label.npz", center=[e.circle.x, e.circle.y],
                     radius=e.circle.r)
            # gs_sdk's labelling tool also saves the press with its circle drawn over it
            drawn = frame.copy()
            drawn[int(e.circle.y), :] = 255
            write_png(dst / rel / "labeled.png", drawn)
        rows.append(f"{rel},{2 * e.ball_radius_mm}")
    (dst / "catalog.csv").write_text("\n".join(rows) + "\n")
    (dst / "sensor.yaml").write_text(f"device_name: GelSight Mini\nimgh: 120\nimgw: 160\n"
                                     f"ppmm: {MM_PER_PX}\n")
    return dst


def test_gs_sdk_folder_carries_circles_balls_scale_and_background(sim, tmp_path) -> None:
    src = gs_folder(sim, tmp_path / "calib")
    s = import_presses(src, tmp_path / "rec", config=src / "sensor.yaml")
    assert (s.layout, s.presses, s.labelled, s.mm_per_px, s.background) == \
        ("gs_sdk", 10, 10, MM_PER_PX, True)
    assert s.ball_radii_mm == (3.0,)
    m, truth = load_manifest(tmp_path / "rec"), load_manifest(sim)
    presses = [e for e in truth.entries if e.kind == "press"]
    assert [e.id for e in m.entries] == [f"6.000mm-{k}" for k in range(10)]
    for got, want in zip(m.entries, presses, strict=True):
        assert got.circle == want.circle and got.ball_radius_mm == 3.0
        assert np.array_equal(read_image(tmp_path / "rec" / got.source.path),
                              read_image(sim / want.source.path))
    assert m.sessions[0].mm_per_px == (MM_PER_PX, MM_PER_PX)
    assert m.sessions[0].resolution == (120, 160) and m.sessions[0].sensor == "gelsight"
    assert not (src / "recordings.json").exists()  # the source folder is left alone


def test_cli_import_then_calibrate(sim, tmp_path) -> None:
    src = gs_folder(sim, tmp_path / "calib", skip_label=3)
    res = CliRunner().invoke(app, ["import-presses", str(src), "--out", str(tmp_path / "rec"),
                                   "--config", str(src / "sensor.yaml")])
    assert res.exit_code == 0, res.output
    assert "10 presses (9 with labelled circles) from a gs_sdk folder" in res.stdout
    assert "0.06 mm/px" in res.stdout
    out = tmp_path / "cal.safetensors"
    res = CliRunner().invoke(app, ["calibrate", str(tmp_path / "rec"), "--out", str(out),
                                   "--holdout", "2", "--seed", "1"])
    assert res.exit_code == 0, res.output
    assert "(1 circles detected)" in res.stdout  # the press without a label is detected
    from vtsbench.depth.calibration import load_calibration

    cal = load_calibration(out, resolution=(120, 160))
    # Measured: 0.029 mm held out over 2 presses, trained on 8 (one circle detected).
    assert cal.fit["holdout_mean"]["plane_aligned_rmse_mm"] < 0.05


def test_jpeg_presses_and_background(sim, tmp_path) -> None:
    """A camera that saves JPEG: gelsight.jpg and background.jpg are read like the PNGs."""
    import cv2

    src = gs_folder(sim, tmp_path / "calib")
    for png in [src / "background.png", *src.glob("*/*/gelsight.png")]:
        cv2.imwrite(str(png.with_suffix(".jpg")), cv2.imread(str(png)),
                    [cv2.IMWRITE_JPEG_QUALITY, 90])
        png.unlink()
    s = import_presses(src, tmp_path / "rec", config=src / "sensor.yaml")
    assert s.presses == 10 and s.background
    m = load_manifest(tmp_path / "rec")
    assert m.sessions[0].background.endswith("background.jpg")
    assert all(e.source.path.endswith("gelsight.jpg") for e in m.entries)


def test_import_in_place_and_overwrite(sim, tmp_path) -> None:
    src = gs_folder(sim, tmp_path / "calib", labels=False)
    s = import_presses(src, src, mm_per_px=0.05)
    assert s.labelled == 0 and s.mm_per_px == 0.05
    m = load_manifest(src)
    assert m.entries[0].source.path == "6.000mm/0/gelsight.png"
    with pytest.raises(VtsError, match="already exists"):
        import_presses(src, src)
    import_presses(src, src, overwrite=True, config=src / "sensor.yaml")
    assert load_manifest(src).sessions[0].mm_per_px == (MM_PER_PX, MM_PER_PX)


def _edit(src: Path, case: str) -> None:
    """Break one thing of a gs_sdk folder."""
    cat = src / "catalog.csv"
    if case == "no catalog":
        cat.unlink()
    elif case == "no column":
        cat.write_text(cat.read_text().replace("diameter(mm)", "size"))
    elif case.startswith("row "):
        lines = cat.read_text().splitlines()
        lines[2] = case[4:]
        cat.write_text("\n".join(lines) + "\n")
    elif case == "no image":
        (src / "6.000mm/4/gelsight.png").unlink()
        write_png(src / "6.000mm/4/labeled.png", np.zeros((120, 160, 3), np.uint8))
    elif case == "no folder":
        import shutil

        shutil.rmtree(src / "6.000mm/4")
    elif case == "two images":
        import cv2

        img = cv2.imread(str(src / "6.000mm/4/gelsight.png"))
        (src / "6.000mm/4/gelsight.png").unlink()
        cv2.imwrite(str(src / "6.000mm/4/gelsight.jpg"), img)
        cv2.imwrite(str(src / "6.000mm/4/gelsight.bmp"), img)
    elif case == "other size":
        write_png(src / "6.000mm/5/gelsight.png", np.zeros((100, 160, 3), np.uint8))
    elif case == "background size":
        write_png(src / "background.png", np.zeros((120, 150, 3), np.uint8))
    elif case == "not an image":
        (src / "6.000mm/2/gelsight.png").write_bytes(b"<html>not a png</html>")


@pytest.mark.parametrize("case, match", [
    ("no catalog", "no catalog.csv: not a gs_sdk calibration folder"),
    ("no column", "catalog has no 'diameter(mm)' column"),
    ("row ../../etc,6.0", "must be a folder inside the calibration folder"),
    ("row /abs/1,6.0", "must be a folder inside the calibration folder"),
    ("row 6.000mm/1,nan", "row 3: diameter 'nan' is not a positive size"),
    ("row 6.000mm/1,-6", "row 3: diameter '-6' is not a positive size"),
    ("row 6.000mm/1,six", "row 3: diameter 'six' is not a number"),
    ("row 6.000mm/0,6.0", "row 3: '6.000mm/0' is listed twice"),
    ("no image", "no gelsight.png (or .jpg...) for the catalog's '6.000mm/4'"),
    ("no folder", "no folder for the catalog's '6.000mm/4'"),
    ("two images", "2 images named gelsight: gelsight.bmp, gelsight.jpg"),
    ("other size", "frame is 100x160, the first press 120x160"),
    ("background size", "background is 120x150, the presses 120x160"),
    ("not an image", "gelsight.png"),
])
def test_bad_gs_sdk_folder_is_one_line_and_writes_nothing(sim, tmp_path, case, match) -> None:
    src = gs_folder(sim, tmp_path / "calib")
    _edit(src, case)
    res = CliRunner().invoke(app, ["import-presses", str(src), "--out", str(tmp_path / "rec")])
    assert res.exit_code == 2, res.output
    assert match in res.stderr and len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert "Traceback" not in res.output
    assert not (tmp_path / "rec" / "recordings.json").exists()


def _label(path: Path, **arrays) -> Path:
    np.savez(path, **arrays)
    return path


def test_bad_label_files(tmp_path) -> None:
    assert read_label(_label(tmp_path / "ok.npz", center=np.array([3, 4]), radius=np.int64(9))
                      ) == Circle(3.0, 4.0, 9.0)
    cases = {
        "nan": ({"center": [np.nan, 1.0], "radius": 5}, "must be finite"),
        "zero": ({"center": [1.0, 1.0], "radius": 0}, "radius 0 is not positive"),
        "norad": ({"center": [1.0, 1.0]}, "no 'radius' array"),
        "shape": ({"center": [1.0, 1.0, 2.0], "radius": 5}, "must hold x and y"),
        "text": ({"center": np.array(["a", "b"]), "radius": 5}, "must be numbers"),
        "pickle": ({"center": np.array([{"x": 1}, 2], dtype=object), "radius": 5},
                   "not a readable label file"),
    }
    for name, (arrays, match) in cases.items():
        with pytest.raises(VtsError, match=match):
            read_label(_label(tmp_path / f"{name}.npz", **arrays))
    # an archive that unpacks far beyond a label's size is refused before it is unpacked
    bomb = tmp_path / "bomb.npz"
    with zipfile.ZipFile(bomb, "w", compression=zipfile.ZIP_DEFLATED) as zf, \
            zf.open("center.npy", "w") as fh:
        np.lib.format.write_array(fh, np.zeros(1 << 19))  # 4 MiB of zeros, ~4 kB packed
    assert bomb.stat().st_size < 50_000
    with pytest.raises(VtsError, match="unpacks to more than"):
        read_label(bomb)
    (tmp_path / "junk.npz").write_bytes(b"PK\x03\x04 not really")
    with pytest.raises(VtsError, match="not a readable label file"):
        read_label(tmp_path / "junk.npz")


@pytest.mark.parametrize("text, match", [
    ("imgh: 120\n", "no 'ppmm'"),
    ("ppmm: [1, 2\n", "invalid YAML at line"),
    ("ppmm: .nan\n", "is not a positive number"),
    ("ppmm: -0.06\n", "is not a positive number"),
    ("ppmm: true\n", "is not a positive number"),
    ("- 1\n- 2\n", "no 'ppmm'"),
])
def test_bad_sensor_config(sim, tmp_path, text, match) -> None:
    src = gs_folder(sim, tmp_path / "calib")
    (src / "sensor.yaml").write_text(text)
    with pytest.raises(VtsError, match=match):
        import_presses(src, tmp_path / "rec", config=src / "sensor.yaml")


def test_config_that_disagrees_is_a_warning(sim, tmp_path) -> None:
    src = gs_folder(sim, tmp_path / "calib")
    (src / "sensor.yaml").write_text("ppmm: 0.0634\nimgh: 240\nimgw: 320\n")
    said: list[str] = []
    s = import_presses(src, tmp_path / "rec", config=src / "sensor.yaml", mm_per_px=0.06,
                       warn=said.append)
    assert s.mm_per_px == 0.06
    assert any("ppmm 0.0634" in w for w in said) and any("240x320" in w for w in said)


def test_taxim_pack_through_the_command(tmp_path) -> None:
    rng = np.random.default_rng(0)
    np.savez(tmp_path / "p.npz", f0=rng.integers(0, 255, (12, 16, 3), dtype=np.uint8),
             imgs=rng.integers(0, 255, (3, 12, 16, 3), dtype=np.uint8),
             touch_center=np.array([[5.0, 6.0], [7.0, 6.5], [8.0, 4.0]]),
             touch_radius=np.array([3.0, 4.0, 3.5]))
    res = CliRunner().invoke(app, ["import-presses", str(tmp_path / "p.npz"), "--out",
                                   str(tmp_path / "rec"), "--sensor", "lab-gs"])
    assert res.exit_code == 0, res.output
    assert "3 presses (3 with labelled circles) from a taxim pack" in res.stdout
    assert "using Taxim's dataPack_small" in res.stderr
    m = load_manifest(tmp_path / "rec")
    assert m.sessions[0].sensor == "lab-gs" and m.entries[1].circle.r == 4.0
    res = CliRunner().invoke(app, ["import-presses", str(tmp_path / "p.npz"), "--out",
                                   str(tmp_path / "rec"), "--ball-radius-mm", "2.35",
                                   "--mm-per-px", "0.051"])
    assert res.exit_code == 2 and "already exists" in res.stderr
    res = CliRunner().invoke(app, ["import-presses", str(tmp_path / "p.npz"), "--out",
                                   str(tmp_path / "rec"), "--ball-radius-mm", "2.35",
                                   "--mm-per-px", "0.051", "--overwrite"])
    assert res.exit_code == 0 and "using Taxim" not in res.stderr
    assert load_manifest(tmp_path / "rec").entries[0].ball_radius_mm == 2.35
    res = CliRunner().invoke(app, ["import-presses", str(tmp_path / "none"), "--out",
                                   str(tmp_path / "r2")])
    assert res.exit_code == 2 and "not found" in res.stderr
    res = CliRunner().invoke(app, ["import-presses", "/dev/null", "--out", str(tmp_path / "r3")])
    assert res.exit_code == 2 and "not a folder or a regular file" in res.stderr


def test_ball_radius_is_refused_for_a_gs_sdk_folder(sim, tmp_path) -> None:
    src = gs_folder(sim, tmp_path / "calib")
    with pytest.raises(VtsError, match="catalog gives each press's ball diameter"):
        import_presses(src, tmp_path / "rec", ball_radius_mm=3)


@pytest.mark.real
def test_real_taxim_presses_laid_out_by_gs_sdk_match_the_pack(tmp_path) -> None:
    """The same real presses through both layouts: the same circles and the same pixels."""
    import cv2

    pack = real_dir("taxim_gelsight_ball") / "dataPack_small.npz"
    with np.load(pack) as z:
        f0, imgs, centre, radius = z["f0"], z["imgs"], z["touch_center"], z["touch_radius"]
    src = tmp_path / "calib"
    rows = ["experiment_reldir,diameter(mm)"]
    for k, img in enumerate(imgs):  # as gs_sdk's scripts write them: BGR through OpenCV
        (src / f"4.000mm/{k}").mkdir(parents=True)
        cv2.imwrite(str(src / f"4.000mm/{k}/gelsight.png"), img[..., ::-1])
        np.savez(src / f"4.000mm/{k}/label.npz", center=centre[k], radius=radius[k])
        rows.append(f"4.000mm/{k},4.0")
    cv2.imwrite(str(src / "background.png"), f0[..., ::-1])
    (src / "catalog.csv").write_text("\n".join(rows) + "\n")
    import_presses(src, tmp_path / "gs", mm_per_px=0.1245)
    import_presses(pack, tmp_path / "tx")
    a, b = load_manifest(tmp_path / "gs"), load_manifest(tmp_path / "tx")
    assert len(a.entries) == len(b.entries) == 49
    assert a.sessions[0].mm_per_px == b.sessions[0].mm_per_px
    for ea, eb in zip(a.entries, b.entries, strict=True):
        assert ea.circle == eb.circle and ea.ball_radius_mm == eb.ball_radius_mm
        assert np.array_equal(read_image(tmp_path / "gs" / ea.source.path),
                              read_image(tmp_path / "tx" / eb.source.path))
    assert np.array_equal(read_image(tmp_path / "gs" / a.sessions[0].background),
                          read_image(tmp_path / "tx" / b.sessions[0].background))


def test_commands_on_an_unimported_folder_or_pack_point_to_the_import(sim, tmp_path) -> None:
    src = gs_folder(sim, tmp_path / "calib")
    res = CliRunner().invoke(app, ["calibrate", str(src), "--out", str(tmp_path / "c.st")])
    assert res.exit_code == 2 and len(res.stderr.strip().splitlines()) == 1
    assert f"`vtsbench import-presses {src} --out REC`" in res.stderr
    pack = tmp_path / "p.npz"
    np.savez(pack, f0=np.zeros((4, 4, 3), np.uint8))
    res = CliRunner().invoke(app, ["calibrate", str(pack), "--out", str(tmp_path / "c.st")])
    assert res.exit_code == 2 and f"`vtsbench import-presses {pack} --out REC`" in res.stderr
    res = CliRunner().invoke(app, ["calibrate", str(tmp_path), "--out", str(tmp_path / "c.st")])
    assert res.exit_code == 2 and "write one with `vtsbench manifest`" in res.stderr


def _small_pack(path: Path, n: int = 4) -> None:
    rng = np.random.default_rng(1)
    np.savez(path, f0=rng.integers(0, 255, (12, 16, 3), dtype=np.uint8),
             imgs=rng.integers(0, 255, (n, 12, 16, 3), dtype=np.uint8),
             touch_center=rng.uniform(4, 8, (n, 2)), touch_radius=rng.uniform(2, 4, n))


@pytest.mark.parametrize("again", [False, True])
def test_taxim_import_killed_at_every_write_never_looks_done(monkeypatch, tmp_path,
                                                             again) -> None:
    """Killed at each atomic write (every frame, then recordings.json), a first import and a
    re-import over a finished one leave no recordings.json; a rerun then completes."""
    from tests.fixtures.faults import Crash, FailingOs, count_renames
    from vtsbench import atomic

    pack = tmp_path / "p.npz"
    _small_pack(pack)
    done = tmp_path / "done"
    n = count_renames(monkeypatch, lambda: import_presses(pack, done))
    assert n == 4 + 1 + 1  # background, four frames, recordings.json last
    for k in range(1, n + 1):
        out = tmp_path / f"k{k}"
        if again:
            import_presses(pack, out)
        monkeypatch.setattr(atomic, "os", FailingOs(k))
        with pytest.raises(Crash):
            import_presses(pack, out, overwrite=again)
        monkeypatch.setattr(atomic, "os", __import__("os"))
        assert not (out / "recordings.json").exists(), k
        import_presses(pack, out, overwrite=True)
        assert load_manifest(out) == load_manifest(done)


def test_gs_sdk_reimport_killed_keeps_the_previous_manifest(sim, monkeypatch, tmp_path) -> None:
    from tests.fixtures.faults import Crash, FailingOs
    from vtsbench import atomic

    src = gs_folder(sim, tmp_path / "calib")
    import_presses(src, tmp_path / "rec", mm_per_px=0.05)
    before = (tmp_path / "rec" / "recordings.json").read_bytes()
    monkeypatch.setattr(atomic, "os", FailingOs(1))
    with pytest.raises(Crash):
        import_presses(src, tmp_path / "rec", overwrite=True, config=src / "sensor.yaml")
    monkeypatch.setattr(atomic, "os", __import__("os"))
    assert (tmp_path / "rec" / "recordings.json").read_bytes() == before
    assert not [p for p in (tmp_path / "rec").iterdir() if p.name != "recordings.json"]


def test_a_catalog_of_two_balls_passes_the_scale_check(sim, tmp_path) -> None:
    """gs_sdk catalogs mix balls: the circles of most presses, on a large ball, are larger than
    the smallest ball allows, and are not taken for a wrong scale."""
    from vtsbench.depth.calibration import load_presses

    src = gs_folder(sim, tmp_path / "calib")
    # three presses said to be of a 2 mm ball with their circles a third the size (the rest
    # are the 6 mm ball's, 18-35 px against the 2 mm ball's 16.7 px)
    rows = (src / "catalog.csv").read_text().splitlines()
    for k in (1, 2, 3):
        rel = rows[k].split(",")[0]
        rows[k] = f"{rel},2.0"
        with np.load(src / rel / "label.npz") as z:
            np.savez(src / rel / "label.npz", center=z["center"], radius=z["radius"] / 3)
    (src / "catalog.csv").write_text("\n".join(rows) + "\n")
    s = import_presses(src, tmp_path / "rec", config=src / "sensor.yaml")
    assert s.ball_radii_mm == (1.0, 3.0)
    presses, _, _, warnings = load_presses(tmp_path / "rec")
    assert len(presses) == 10 and any("several ball radii" in w for w in warnings)


def test_two_folders_with_one_press_id_are_refused(sim, tmp_path) -> None:
    import re
    import shutil

    src = gs_folder(sim, tmp_path / "calib")
    shutil.copytree(src / "6.000mm/1", src / "6.000mm+1")  # both become the id 6.000mm-1
    (src / "catalog.csv").write_text((src / "catalog.csv").read_text() + "6.000mm+1,6.0\n")
    with pytest.raises(VtsError, match=re.escape("map to the press id '6.000mm-1'")):
        import_presses(src, tmp_path / "rec")
