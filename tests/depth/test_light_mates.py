"""Presses taken under another light than the background: found among the presses, their circles
checked against presses of their own light (contacts left out), a frame without contact under
that light given no circle, and a contact that drowns in the light's change found there."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.fixtures.calibration import save_presses
from tests.fixtures.data import real_dir
from vtsbench.depth.background import light_mates, mates_background, share_filled
from vtsbench.depth.calibration import load_presses
from vtsbench.recordings.manifest import Entry, Source
from vtsbench.recordings.media import write_png

SIZE, MPP = (240, 320), 0.05


def _gel(seed: int) -> np.ndarray:
    """A gel's fixed pattern: smooth-ish texture around 1 (H x W x 3)."""
    rng = np.random.default_rng(seed)
    tex = cv2.GaussianBlur(rng.normal(0, 1, (*SIZE, 3)).astype(np.float32), (0, 0), 2.0)
    return 1.0 + 0.08 * tex / tex.std()


def _light(gains: tuple[float, float, float], tilt: float) -> np.ndarray:
    """A light over the gel: a colour times a ramp across the frame."""
    x = np.linspace(-1, 1, SIZE[1], dtype=np.float32)[None, :, None]
    return 100.0 * np.asarray(gains, np.float32) * (1 + tilt * x)


def _pressed(truth: np.ndarray, circles: list, colour: tuple[float, float, float],
             rng: np.random.Generator) -> list[np.ndarray]:
    """A frame of `truth` per circle, the disc changed by `colour` (DN) and noise added."""
    yy, xx = np.mgrid[:SIZE[0], :SIZE[1]]
    return [np.clip(truth + ((xx - x) ** 2 + (yy - y) ** 2 <= r * r)[..., None]
                    * np.float32(colour) + rng.normal(0, 1.0, truth.shape), 0, 255)
            .astype(np.uint8) for x, y, r in circles]


def test_light_mates_groups_the_presses_of_another_light() -> None:
    gel, rng = _gel(0), np.random.default_rng(1)
    one, two = _light((1, 1, 1), 0.2), _light((1.4, 0.8, 1.1), -0.3)

    def shot(light: np.ndarray) -> np.ndarray:
        return np.clip(gel * light + rng.normal(0, 1.5, gel.shape), 0, 255).astype(np.uint8)

    bg = shot(one)
    frames = {f"a{i}": shot(one) for i in range(6)} | {f"b{i}": shot(two) for i in range(3)}
    groups = light_mates(frames, bg)
    assert sorted(groups) == ["b0", "b1", "b2"]
    assert all(sorted(v) == sorted({"b0", "b1", "b2"} - {k}) for k, v in groups.items())
    # one light throughout, or a single far press with nobody of its light: nothing
    assert light_mates({k: v for k, v in frames.items() if k[0] == "a"}, bg) == {}
    assert light_mates({k: v for k, v in frames.items() if k != "b1" and k != "b2"}, bg) == {}
    assert light_mates({}, bg) == {}


def test_mates_background_leaves_their_contacts_out_and_fills_between() -> None:
    """Two presses under another light, their contacts overlapping: the background made of them
    is that light's no-contact frame within a few DN everywhere, inside the hole where neither
    is free too (the light's change divides the gel's pattern out and is carried in smoothly),
    and it has no ring where the mix of mates changes."""
    gel, rng = _gel(2), np.random.default_rng(3)
    bg_light, light = _light((1, 1, 1), 0.0), _light((1.3, 0.9, 0.8), 0.4)
    truth = gel * light
    circles = [(140.0, 120.0, 30.0), (180.0, 120.0, 30.0)]
    frames = _pressed(truth, circles, (60, -40, 30), rng)
    bg = np.clip(gel * bg_light, 0, 255).astype(np.uint8)
    ref, filled = mates_background(frames, circles, bg)
    err = np.abs(ref.astype(np.float32) - truth)
    assert filled.any() and not filled.all()
    assert float(np.median(err[filled])) < 4.0 and float(err[filled].max()) < 15.0
    assert float(np.percentile(err, 99)) < 6.0
    # no contact left in it: the largest error is nowhere near a contact's 60 DN
    assert float(err.max()) < 20.0
    assert share_filled((160.0, 120.0, 10.0), filled) == 1.0
    assert share_filled((40.0, 40.0, 10.0), filled) == 0.0
    assert share_filled((-50.0, 40.0, 10.0), filled) == 1.0  # off the frame


def test_mates_background_outvotes_a_contact_whose_circle_is_not_known() -> None:
    """Four mates, one of whose contacts has no circle (its detection failed): with three
    others to outvote it, the background shows no trace of it; two mates alone cannot."""
    gel, rng = _gel(4), np.random.default_rng(5)
    bg_light, light = _light((1, 1, 1), 0.0), _light((0.8, 1.2, 1.0), -0.3)
    truth = gel * light
    yy, xx = np.mgrid[:SIZE[0], :SIZE[1]]
    circles = [(60.0, 60.0, 25.0), (250.0, 60.0, 25.0), (60.0, 180.0, 25.0), (160.0, 120.0, 30.0)]
    frames = _pressed(truth, circles, (50, -45, 35), rng)
    bg = np.clip(gel * bg_light, 0, 255).astype(np.uint8)
    ref, filled = mates_background(frames, [*circles[:3], None], bg)
    assert not filled.any()
    inside = (xx - 160) ** 2 + (yy - 120) ** 2 <= 30 ** 2
    err = np.abs(ref.astype(np.float32) - truth).sum(-1)
    assert float(np.median(err[inside])) < 6.0 and float(np.percentile(err[inside], 95)) < 15.0
    # two mates, the unknown contact's among them: half of it stays (a reason to leave such a
    # mate out when fewer than three)
    ref2, _ = mates_background([frames[0], frames[3]], [circles[0], None], bg)
    err2 = np.abs(ref2.astype(np.float32) - truth).sum(-1)
    assert float(np.median(err2[inside])) > 30.0


def _two_lights(folder: Path, gel: str) -> tuple[Path, dict[str, tuple[float, float, float]]]:
    """Six presses under the simulator's three coloured zones with their background, four
    more and a frame without contact under red, green, blue and white side lights (the same
    gel and camera): a recordings folder without labels, and the exact circles."""
    from vtsbench.sim.appearance import background, sensor_appearance
    from vtsbench.sim.optics import Capture, sensor
    from vtsbench.sim.plan import press_scene
    from vtsbench.sim.relight import relight
    from vtsbench.sim.scene import render

    app = sensor_appearance("markers")
    if gel == "none":
        app = dataclasses.replace(app, marker_darkness=0.0)
    cap, seed = Capture(gel=0), 0
    fields = {k: sensor(*SIZE, MPP, lights=k) for k in ("zones3", "sides4")}
    (folder / "p").mkdir(parents=True)
    write_png(folder / "bg.png", background(app, fields["zones3"], cap,
                                            np.random.default_rng([seed, 1])))
    entries, exact = [], {}
    for i in range(10):
        rng = np.random.default_rng([seed, 2, i])
        scene = press_scene(rng, SIZE, MPP, 2, app)
        truth = render(scene.with_effects(dataclasses.replace(scene.effects, noise=False)))
        lights = "zones3" if i < 6 else "sides4"
        frame = relight(truth.grad, fields[lights], cap, rng, app)[0]
        write_png(folder / "p" / f"{i}.png", frame)
        (cx, cy), r = scene.centers_px[0], math.sqrt(truth.contact[0].sum() / math.pi)
        exact[f"p{i}"] = (cx, cy, r)
        entries.append(Entry(f"p{i}", "press", "s0", Source(f"p/{i}.png"), ball_radius_mm=3.0))
    write_png(folder / "p" / "nc.png", background(app, fields["sides4"], cap,
                                                  np.random.default_rng([seed, 1])))
    entries.append(Entry("nc", "press", "s0", Source("p/nc.png"), ball_radius_mm=3.0))
    save_presses(folder, entries, SIZE, MPP)
    return folder, exact


@pytest.mark.parametrize("gel", ["none", "markers"])
def test_a_frame_without_contact_under_another_light_gets_no_circle(tmp_path, gel) -> None:
    """Against the background alone, the other light's change can pass the check as a contact
    (with markers, the frame without contact was used with a circle in a corner of the frame).
    Against the presses of its light it shows none and is dropped, every circle used lies on
    its contact, and the presses of the other light are named."""
    rec, exact = _two_lights(tmp_path / "rec", gel)
    _, _, setup, warns = load_presses(rec, background=rec / "bg.png")
    rows = {r["id"]: r for r in setup["presses"]}
    assert rows["nc"]["status"] == "dropped", rows["nc"]
    for k, (x, y, r) in exact.items():
        c = rows[k]["circle"]
        if rows[k]["status"] != "dropped":
            assert math.hypot(c["x"] - x, c["y"] - y) < 10 and abs(c["r"] / r - 1) < 0.15, (k, c)
    used = [k for k in exact if k >= "p6" and rows[k]["status"] != "dropped"]
    assert len(used) >= 3, rows
    named = [w for w in warns if "taken under another light or exposure?" in w]
    assert len(named) == 1 and "p6" in named[0] and "p1," not in named[0], warns
    assert not [k for k in exact if k < "p6" and rows[k].get("against_presses")]


def _digit_grey(out: Path) -> Path | None:
    """The DIGIT presses as a monochrome camera would give them, with their labels."""
    from typer.testing import CliRunner

    from vtsbench.cli import app

    src = real_dir("digit_ball_6mm")
    if not (src / "0017.png").is_file():
        return None
    (out / "f").mkdir(parents=True)
    for p in sorted(src.glob("*.png")):
        grey = cv2.cvtColor(cv2.imread(str(p)), cv2.COLOR_BGR2GRAY)
        cv2.imwrite(str(out / "f" / p.name), cv2.merge([grey] * 3))
    res = CliRunner().invoke(app, ["manifest", str(out / "f"), "--pattern", "{name}.png",
                                   "--kind", "press", "--ball-radius-mm", "3", "--circles",
                                   str(src / "sphere.csv"), "--out", str(out / "rec")])
    assert res.exit_code == 0, res.output
    return out / "rec"


def test_digit_0017_in_grey_is_found_against_0016(tmp_path) -> None:
    """DIGIT 0017 (unlabelled, under another light than the 14 labelled presses whose median
    is the background) in grey: against the background no circle is found; against 0016, the
    other press of its light, it is, on its imprint (within 3 px of where the colour frames
    put it, (112.2, 151.2) r 24.0)."""
    rec = _digit_grey(tmp_path)
    if rec is None:
        pytest.skip("DIGIT presses 0016 and 0017 not present")
    _, _, setup, warns = load_presses(rec, mm_per_px=1 / 21.09, estimate_background=True)
    row = next(r for r in setup["presses"] if r["id"] == "0017")
    assert row["status"] == "used" and row["against_presses"] == ["0016"], row
    assert row["against_background"] == "no visible contact: no circle detected", row
    c = row["circle"]
    assert math.hypot(c["x"] - 112.2, c["y"] - 151.2) < 4 and abs(c["r"] / 24.0 - 1) < 0.15, c
    named = [w for w in warns if "0016, 0017 lie far from the background" in w]
    assert len(named) == 1 and setup["background_notes"] == named, warns
    assert any(w.startswith("press 0017: against the background, no visible contact")
               for w in warns), warns
