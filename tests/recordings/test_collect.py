"""`vtsbench collect`: video files and motion logs into a recordings folder, with labels."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from vtsbench.errors import VtsError
from vtsbench.labels import Thresholds
from vtsbench.recordings import media
from vtsbench.recordings.collect import CollectOptions, collect, window_labels
from vtsbench.recordings.manifest import MANIFEST_NAME, Mount, load_manifest
from vtsbench.recordings.motionlog import read_motion_log

H, W = 96, 128
FPS = 10.0
MM_PER_PX = 0.1
N_BG = 5  # still background frames at the start of every test video
STEP_PX = 2  # blob speed while sliding, px per frame (0.2 mm per frame)
BLOB_RGB = (200, 60, 40)  # reddish, so a swapped channel order shows


def blob_frame(cx: float | None, cy: float = 0.0, r: float = 12.0) -> np.ndarray:
    """A flat gray RGB frame with a checker-textured disc centred at (cx, cy), rows down."""
    img = np.full((H, W, 3), 128, np.uint8)
    if cx is None:
        return img
    yy, xx = np.mgrid[:H, :W]
    inside = (xx - cx) ** 2 + (yy - cy) ** 2 <= r * r
    checker = ((np.floor((xx - cx) / 4) + np.floor((yy - cy) / 4)) % 2).astype(bool)
    img[inside] = BLOB_RGB
    img[inside & checker] = (230, 110, 90)
    return img


def write_video(path: Path, frames: list[np.ndarray], size: tuple[int, int] = (H, W)) -> Path:
    import cv2

    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), FPS, (size[1], size[0]))
    assert vw.isOpened()
    for f in frames:
        vw.write(np.ascontiguousarray(f[:, :, ::-1]))  # the writer takes BGR
    vw.release()
    return path


# The motion video: 5 background frames, then four 8-frame phases (still, slide right, slide
# up, press) covered by the log, then 8 still frames past the end of the log.
N_LOGGED = N_BG + 32  # frames 0..36 are in the log
N_MOTION = N_LOGGED + 8


def stage(i: int) -> tuple[float, float, float, float]:
    """Blob centre (px, rows down), radius (px) and stage z (mm) at frame i."""
    cx = 40 + STEP_PX * np.clip(i - 13, 0, 7)
    cy = 48 - STEP_PX * np.clip(i - 21, 0, 7)
    z = -0.5 if i < N_BG else 0.3 + 0.1 * np.clip(i - 29, 0, 7)
    r = 12 + 0.8 * np.clip(i - 29, 0, 7)
    return float(cx), float(cy), float(r), float(z)


def motion_log_rows(n: int = N_LOGGED) -> list[str]:
    rows = ["t_s,x_mm,y_mm,z_mm,extra"]
    for i in range(n):
        cx, cy, _, z = stage(i)
        # stage x along image x, stage y up the image (rows decrease)
        rows.append(f"{i / FPS:.6f},{(cx - 40) * MM_PER_PX:.6f},{(48 - cy) * MM_PER_PX:.6f},"
                    f"{z:.6f},0")
    return rows


@pytest.fixture(scope="module")
def media_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("media")
    frames = []
    for i in range(N_MOTION):
        cx, cy, r, _ = stage(i)
        frames.append(blob_frame(None) if i < N_BG else blob_frame(cx, cy, r))
    write_video(d / "motion.avi", frames)
    (d / "motion.csv").write_text("\n".join(motion_log_rows()) + "\n")
    # presses: background, then contact in frames 10-14 and 20-24 only
    press = [blob_frame(40, 48) if 10 <= i < 15 or 20 <= i < 25 else blob_frame(None)
             for i in range(28)]
    write_video(d / "press.avi", press)
    log = ["t_s,x_mm,y_mm,z_mm"] + [
        f"{i / FPS},0,0,{0.5 if 10 <= i < 15 or 20 <= i < 25 else -0.2}" for i in range(28)]
    (d / "press.csv").write_text("\n".join(log) + "\n")
    write_video(d / "small.avi", [np.full((48, 64, 3), 128, np.uint8)] * 20, size=(48, 64))
    (d / "broken.avi").write_bytes(b"not a video at all " * 64)
    return d


def opts(d: Path, **kw) -> CollectOptions:
    base = dict(source=str(d / "motion.avi"), session="s1", sensor="test", mm_per_px=MM_PER_PX,
                background_frames=N_BG, motion_log=d / "motion.csv")
    base.update(kw)
    return CollectOptions(**base)


def run(out: Path, o: CollectOptions):
    return collect(out, o, progress=False)


# -- sequences and labels --------------------------------------------------------------------


def test_sequences_labelled_from_the_motion_log(media_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "rec"
    res = run(out, opts(media_dir, object="blob"))
    m = load_manifest(out)
    assert [e.id for e in m.entries] == [e.id for e in res.entries]
    s = m.session("s1")
    assert s.resolution == (H, W) and s.fps == FPS and s.mm_per_px == (MM_PER_PX, MM_PER_PX)
    assert (out / s.background).is_file() and s.background == "s1/background.png"
    assert res.take == "001" and res.frames_read == N_MOTION
    got = [(e.source.start, e.source.stop, e.labels.state, e.labels.direction) for e in m.entries]
    assert got == [(0, 8, "static", None), (8, 16, "slip", 0), (16, 24, "slip", 2),
                   (24, 32, "press", None), (32, 40, None, None)]
    assert all(e.kind == "sequence" and e.object == "blob" and e.take == "001" for e in m.entries)
    assert all(e.source.path == "s1/001" for e in m.entries)
    static, right, up, press, unknown = m.entries
    assert static.labels.motion_mm == (0.0, 0.0) and static.labels.press_depth_mm == 0.3
    assert right.labels.motion_mm == pytest.approx((7 * STEP_PX * MM_PER_PX, 0.0))
    assert up.labels.motion_mm == pytest.approx((0.0, 7 * STEP_PX * MM_PER_PX))
    assert press.labels.press_depth_mm == pytest.approx(1.0)
    assert unknown.labels.to_dict() == {}  # the window lies past the end of the log
    assert right.meta["capture_frame"] == N_BG + 8


def test_written_frames_equal_the_decoded_video(media_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "rec"
    run(out, opts(media_dir))
    decoded = media.read_frames(media_dir / "motion.avi")
    folder = out / "s1" / "001"
    names = sorted(p.name for p in folder.iterdir())
    assert names == [f"{i:06d}.png" for i in range(N_BG, N_MOTION)]
    written = media.read_frames(folder)
    assert np.array_equal(written, decoded[N_BG:])
    # RGB order: the reddish blob stays red after the round trip
    r, _, b = written[0][48, 40].astype(int)
    assert r > 150 and b < 100 and r > b + 80
    # the background is the median of the still leading frames
    bg = media.read_image(out / "s1" / "background.png")
    assert np.abs(bg.astype(int) - np.median(decoded[:N_BG], axis=0)).max() <= 1


def test_mount_rotation_maps_stage_x_to_image_up(media_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "rec"
    run(out, opts(media_dir, mount_rotation_deg=90.0))
    m = load_manifest(out)
    assert m.session("s1").mount == Mount(90.0, False)
    right, up = m.entries[1], m.entries[2]
    assert (right.labels.state, right.labels.direction) == ("slip", 2)  # stage +x -> image up
    assert (up.labels.state, up.labels.direction) == ("slip", 4)  # stage +y -> image left
    assert right.labels.motion_mm == pytest.approx((0.0, 1.4))


def test_window_labels_mirror_thresholds_and_release(tmp_path: Path) -> None:
    log_path = tmp_path / "log.csv"
    log_path.write_text("t_s,x_mm,y_mm,z_mm\n0,0,0,0.5\n1,1,0,0.5\n2,1,0,0.1\n3,1.03,0,0.13\n")
    log = read_motion_log(log_path)
    thr = Thresholds()
    lab = window_labels(log, 0, 10, 10.0, 0.0, Mount(0.0, True), thr)
    assert (lab.state, lab.direction) == ("slip", 4)  # mirrored: stage +x -> image left
    lab = window_labels(log, 10, 20, 10.0, 0.0, Mount(), thr)
    assert (lab.state, lab.direction, lab.press_depth_mm) == (None, None, 0.1)  # a release
    lab = window_labels(log, 20, 30, 10.0, 0.0, Mount(), thr)
    assert lab.state == "static"  # 0.03 mm sideways and up: below both thresholds
    lab = window_labels(log, 20, 30, 10.0, 0.0, Mount(), Thresholds(0.02, 0.02))
    assert lab.state == "slip"
    assert window_labels(log, 25, 35, 10.0, 0.0, Mount(), thr).to_dict() == {}
    # the offset shifts frames into the log: frame 0 at t = 1 s
    assert window_labels(log, 0, 10, 10.0, 1.0, Mount(), thr).state is None
    assert window_labels(None, 0, 10, 10.0, 0.0, Mount(), thr).to_dict() == {}


def test_without_a_log_labels_are_unknown_and_stride(media_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "rec"
    res = run(out, opts(media_dir, motion_log=None, window=6, stride=4))
    m = load_manifest(out)
    assert [(e.source.start, e.source.stop) for e in m.entries] == [
        (s, s + 6) for s in range(0, 40 - 6 + 1, 4)]
    assert all(e.labels.to_dict() == {} for e in res.entries)
    # frames after the last window are not kept
    assert len(list((out / "s1" / "001").iterdir())) == 4 * 8 + 6


def test_max_frames_and_log_offset(media_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "rec"
    res = run(out, opts(media_dir, max_frames=N_BG + 16, log_offset_s=0.8))
    assert res.frames_read == N_BG + 16
    # frame i is at t = i / 10 + 0.8: the first window (frames 5..12) reads the log at
    # frames 13..20, the slide to the right
    assert [(e.labels.state, e.labels.direction) for e in res.entries] == [("slip", 0),
                                                                           ("slip", 2)]


# -- static and press ------------------------------------------------------------------------


def test_static_mode(media_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "rec"
    res = run(out, opts(media_dir, kind="static", every=4, object="blob"))
    m = load_manifest(out)
    frames = list(range(N_BG, N_MOTION, 4))
    assert [e.meta["capture_frame"] for e in m.entries] == frames
    assert [e.source.path for e in m.entries] == [f"s1/001/{i:06d}.png" for i in frames]
    assert all(e.kind == "static" and e.source.frame is None for e in m.entries)
    depths = [e.labels.press_depth_mm for e in res.entries]
    assert depths[0] == 0.3 and depths[-1] is None  # frame 41 is past the end of the log
    decoded = media.read_frames(media_dir / "motion.avi")
    assert np.array_equal(media.read_image(out / m.entries[2].source.path), decoded[frames[2]])


def test_press_mode_keeps_contact_frames(media_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "rec"
    o = opts(media_dir, source=str(media_dir / "press.avi"), motion_log=media_dir / "press.csv",
             kind="press", every=3, ball_radius_mm=3.0)
    run(out, o)
    m = load_manifest(out)
    assert [e.meta["capture_frame"] for e in m.entries] == [10, 13, 20, 23]
    assert all(e.kind == "press" and e.ball_radius_mm == 3.0 for e in m.entries)
    assert all(e.labels.press_depth_mm == 0.5 for e in m.entries)
    assert all(e.meta["contact_fraction"] > 0.01 for e in m.entries)
    assert sorted(p.name for p in (out / "s1" / "001").iterdir()) == [
        f"{i:06d}.png" for i in (10, 13, 20, 23)]


def test_press_needs_a_ball_radius(media_dir: Path, tmp_path: Path) -> None:
    with pytest.raises(VtsError, match="--ball-radius"):
        run(tmp_path / "rec", opts(media_dir, kind="press"))
    assert not (tmp_path / "rec").exists()


def test_press_without_contact_is_an_error(media_dir: Path, tmp_path: Path) -> None:
    with pytest.raises(VtsError, match="contact"):
        run(tmp_path / "rec", opts(media_dir, source=str(media_dir / "small.avi"),
                                   motion_log=None, kind="press", ball_radius_mm=2.0))
    assert not (tmp_path / "rec").exists()


# -- appending -------------------------------------------------------------------------------


def test_append_adds_takes_and_sessions(media_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "rec"
    run(out, opts(media_dir))
    res = run(out, opts(media_dir, sensor=None, mm_per_px=None, kind="static", every=10,
                        append=True))
    assert res.take == "002" and not res.new_session
    res = run(out, opts(media_dir, sensor=None, mm_per_px=None, take="left", append=True))
    assert res.take == "left"
    res = run(out, opts(media_dir, session="s2", sensor="other", append=True))
    assert res.new_session and res.take == "001"
    m = load_manifest(out)
    assert [s.id for s in m.sessions] == ["s1", "s2"]
    assert (out / "s2" / "background.png").is_file()
    takes = sorted({(e.session, e.take) for e in m.entries})
    assert takes == [("s1", "001"), ("s1", "002"), ("s1", "left"), ("s2", "001")]
    assert len({e.id for e in m.entries}) == len(m.entries)
    with pytest.raises(VtsError, match="already has a take left"):
        run(out, opts(media_dir, sensor=None, mm_per_px=None, take="left", append=True))


def test_append_checks_the_session(media_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "rec"
    run(out, opts(media_dir))
    before = (out / MANIFEST_NAME).read_text()
    with pytest.raises(VtsError, match=r"48x64 pixels, unlike session s1's resolution \(96x128\)"):
        run(out, opts(media_dir, source=str(media_dir / "small.avi"), sensor=None,
                      mm_per_px=None, motion_log=None, append=True))
    with pytest.raises(VtsError, match="mm_per_px"):
        run(out, opts(media_dir, sensor=None, mm_per_px=0.5, append=True))
    with pytest.raises(VtsError, match="frame rate"):
        run(out, opts(media_dir, sensor=None, mm_per_px=None, fps=30.0, append=True))
    assert (out / MANIFEST_NAME).read_text() == before
    assert sorted(p.name for p in (out / "s1").iterdir()) == ["001", "background.png"]


def test_existing_out_needs_append_or_overwrite(media_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "rec"
    run(out, opts(media_dir))
    with pytest.raises(VtsError, match="--append"):
        run(out, opts(media_dir))
    res = run(out, opts(media_dir, kind="static", overwrite=True))
    assert [e.kind for e in load_manifest(out).entries] == ["static"] * len(res.entries)


def test_an_interrupted_run_leaves_the_manifest_untouched(media_dir: Path, tmp_path: Path,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "rec"
    run(out, opts(media_dir))
    before = (out / MANIFEST_NAME).read_text()
    calls = []
    real = media.write_png

    def flaky(path: Path, rgb: np.ndarray, compression: int = 1) -> None:
        calls.append(path)
        if len(calls) == 12:
            raise KeyboardInterrupt
        real(path, rgb, compression)

    monkeypatch.setattr(media, "write_png", flaky)
    with pytest.raises(KeyboardInterrupt):
        run(out, opts(media_dir, sensor=None, mm_per_px=None, append=True))
    calls.clear()
    with pytest.raises(KeyboardInterrupt):
        run(tmp_path / "new", opts(media_dir))
    assert (out / MANIFEST_NAME).read_text() == before
    assert sorted(p.name for p in (out / "s1").iterdir()) == ["001", "background.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec"]


# -- errors ----------------------------------------------------------------------------------


@pytest.mark.parametrize(("text", "match"), [
    ("t_s,x_mm,y_mm\n0,0,0\n1,0,0\n", "lacks column.*z_mm"),
    ("t_s,x_mm,y_mm,z_mm\n0,0,0,0\n1,0,abc,0\n", "line 3: y_mm is not a number"),
    ("t_s,x_mm,y_mm,z_mm\n0,0,0,0\n1,0,0,0\n1,0,0,0\n", "line 4: t_s 1 is not after"),
    ("t_s,x_mm,y_mm,z_mm\n0,0,0,0\n", "at least 2 rows"),
    ("t_s,x_mm,y_mm,z_mm\n0,0,0,0\n1,0,nan,0\n", "not finite"),
])
def test_bad_motion_log(media_dir: Path, tmp_path: Path, text: str, match: str) -> None:
    log = tmp_path / "bad.csv"
    log.write_text(text)
    with pytest.raises(VtsError, match=match) as err:
        run(tmp_path / "rec", opts(media_dir, motion_log=log))
    msg = str(err.value)
    assert msg.startswith(str(log)) and "\n" not in msg
    assert not (tmp_path / "rec").exists()


def test_bad_sources(media_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    broken = media_dir / "broken.avi"
    with pytest.raises(VtsError, match="cannot") as err:
        run(tmp_path / "rec", opts(media_dir, source=str(broken)))
    assert str(broken) in str(err.value)
    with pytest.raises(VtsError, match="not found"):
        run(tmp_path / "rec", opts(media_dir, source=str(tmp_path / "missing.mp4")))
    with pytest.raises(VtsError, match="camera 57: cannot open camera"):
        run(tmp_path / "rec", opts(media_dir, source="57"))
    assert not (tmp_path / "rec").exists()

    real_init = media.Capture.__init__

    def no_fps(self, source: str) -> None:
        real_init(self, source)
        self.fps = None

    monkeypatch.setattr(media.Capture, "__init__", no_fps)
    with pytest.raises(VtsError, match=r"frame rate unknown.*--fps"):
        run(tmp_path / "rec", opts(media_dir))
    assert run(tmp_path / "rec", opts(media_dir, fps=FPS)).manifest.sessions[0].fps == FPS


# -- command line ----------------------------------------------------------------------------


def test_cli_collects(media_dir: Path, tmp_path: Path) -> None:
    from vtsbench.cli import app

    out = tmp_path / "rec"
    res = CliRunner().invoke(app, [
        "collect", str(out), "--source", str(media_dir / "motion.avi"), "--session", "s1",
        "--sensor", "test", "--mm-per-px", "0.1", "--background-frames", "5", "--motion-log",
        str(media_dir / "motion.csv"), "--mount-rotation", "90", "--object", "blob", "--quiet"])
    assert res.exit_code == 0, res.output
    assert "wrote 5 sequence entries" in res.output
    doc = json.loads((out / MANIFEST_NAME).read_text())
    assert doc["sessions"][0]["mount"] == {"rotation_deg": 90.0, "mirror": False}
    assert doc["entries"][1]["labels"]["direction"] == 2


@pytest.mark.parametrize("source", ["broken.avi", "missing.mp4", "57"])
def test_cli_bad_source_is_one_line(media_dir: Path, tmp_path: Path, source: str) -> None:
    from vtsbench.cli import app

    src = source if source.isdigit() else str(media_dir / source)
    res = CliRunner().invoke(app, ["collect", str(tmp_path / "rec"), "--source", src, "--quiet"])
    assert res.exit_code == 2
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in res.output
    assert not (tmp_path / "rec").exists()
