"""Continuous simulated takes: per-frame labels exact against the motion the renderer used,
the onset frame exact, takes without slip, and the dataset of takes with its samples and
splits."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

import vtsbench
from vtsbench.errors import VtsError
from vtsbench.labels import SLIP_THRESHOLD_MM, STATES, direction_class, label_motion
from vtsbench.sim.appearance import sensor_appearance
from vtsbench.sim.episode_dataset import EpisodeOptions, episode_samples, simulate_episodes
from vtsbench.sim.episodes import LABEL_WINDOW, plan_episodes, render_episode
from vtsbench.sim.simulate import session_capture

SIZE = (48, 64)


def _render(number: int, slip: bool = True, truth: bool = True, plans: tuple = (8, 2, 2)):
    plan = dataclasses.replace(plan_episodes(0, *plans)[number], slip=slip)
    cap = dataclasses.replace(session_capture(0, plan.session)[0], gel=0)
    return render_episode(plan, seed=0, size=SIZE, fps=25.0, seconds=3.0, capture=cap,
                          appearance=sensor_appearance(), truth=truth)


@pytest.mark.parametrize("number", [0, 1, 2])
def test_labels_are_the_rule_on_the_rendered_motion(number: int) -> None:
    ep = _render(number)
    n = len(ep.frames)
    assert ep.frames.shape == (n, *SIZE, 3) and n == 75
    assert ep.depth is not None and ep.contact is not None
    # the renderer's own truth: the object's translation (px, y down) and contact per frame
    from vtsbench.sim.episodes import episode_rng, episode_scene

    scene, *_ = episode_scene(ep.plan, episode_rng(0, ep.plan.number), SIZE, ep.mm_per_px, n)
    c0 = scene.centers_px[0]
    moved = np.array([((x - c0[0]) * ep.mm_per_px, -(y - c0[1]) * ep.mm_per_px)
                      for x, y in scene.centers_px])
    np.testing.assert_allclose(moved, ep.position_mm, atol=1e-9)
    np.testing.assert_array_equal(ep.in_contact, ep.contact.any(axis=(1, 2)))
    contact = ep.contact.any(axis=(1, 2))
    for t in range(n):
        a = max(0, t - LABEL_WINDOW + 1)
        touch = np.flatnonzero(contact[a:t + 1]) + a
        if not len(touch):
            assert ep.states[t] == "static"  # nothing on the gel: by phase
            continue
        d = moved[touch[-1]] - moved[touch[0]]
        if abs(np.hypot(*d) - SLIP_THRESHOLD_MM) < 1e-9:
            continue  # on the threshold itself: float rounding decides
        dz = max(0.0, scene.depths_mm[t]) - max(0.0, scene.depths_mm[a])
        lab = label_motion(d[0], d[1], dz)
        assert ep.states[t] == lab.state, t
        assert ep.directions[t] == lab.direction, t


def test_onset_is_the_first_slip_frame_and_the_phases_hold() -> None:
    ep = _render(0)
    slip = [t for t, s in enumerate(ep.states) if s == "slip"]
    assert ep.onset_frame == slip[0]
    assert ep.slip_onset_s == pytest.approx(slip[0] / 25.0)
    ph = ep.meta["phases"]
    start = ph["hold"] + ph["press"] + ph["contact"]  # the first frame that has moved
    assert ep.phase[start] == "slip" and ep.phase[start - 1] == "contact"
    assert (ep.position_mm[:start] == 0).all() and (ep.position_mm[start] != 0).any()
    # the onset: the first frame whose window has moved the slip threshold
    moved = np.hypot(*(ep.position_mm[start:] - ep.position_mm[start - 1]).T)
    k = int(np.argmax(moved >= SLIP_THRESHOLD_MM))
    assert ep.onset_frame == start + k
    assert ep.direction == direction_class(*ep.position_mm[-1], 0.0)
    assert {ep.directions[t] for t in slip} == {ep.direction}
    assert "press" in ep.states and ep.states[0] == "static"
    assert ep.states[-1] in (None, "static", "slip")


def test_a_take_without_slip() -> None:
    ep = _render(1, slip=False, truth=False)
    assert ep.onset_frame is None and ep.slip_onset_s is None and ep.direction is None
    assert "slip" not in ep.states and "slip" not in ep.phase
    assert (ep.position_mm == 0).all() and ep.depth is None
    assert set(ep.states) <= {"static", "press", None}
    assert None in ep.states  # the release is no state


def test_denser_samples_add_overlapping_windows_with_the_same_labels() -> None:
    ep = _render(0)
    by = {k: {(kind, a): lab for kind, a, lab in episode_samples(ep, stride=k)} for k in (8, 2)}
    slip = {k: sorted(a for kind, a in v if kind == "slip") for k, v in by.items()}
    assert all(a % 8 == 0 for a in slip[8]) and all(a % 2 == 0 for a in slip[2])
    assert set(slip[8]) < set(slip[2]) and len(slip[2]) > 3 * len(slip[8])
    for key, lab in by[8].items():  # every window of stride 8 is one of stride 2, unchanged
        assert by[2][key] == lab
    # the near-onset windows: stride 2 has a slip window ending within 2 frames of the onset
    ends = [a + LABEL_WINDOW - 1 for a in slip[2] if by[2][("slip", a)]["state"] == "slip"]
    assert ep.onset_frame is not None and min(ends) - ep.onset_frame < 2
    statics = {k: [a for kind, a in v if kind == "static"] for k, v in by.items()}
    assert statics[8] == statics[2]  # static frames keep their own stride


def test_plans_and_bad_options() -> None:
    plans = plan_episodes(3, 16, 4, 3)
    assert [p.object for p in plans[:4]] == [p.object for p in plans[4:8]]
    for obj in {p.object for p in plans}:
        assert [p.slip for p in plans if p.object == obj].count(False) == 1
    assert plans == plan_episodes(3, 16, 4, 3)
    with pytest.raises(VtsError, match="at least"):
        render_episode(plans[0], seed=0, size=SIZE, fps=10.0, seconds=2.0)


def test_a_dataset_of_takes(tmp_path: Path) -> None:
    out = tmp_path / "takes"
    opts = EpisodeOptions(6, 3, 2, 25.0, 3.0, SIZE, 0, truth=True)
    simulate_episodes(out, opts, workers=2)
    ds = vtsbench.load(out)
    assert len(ds.episodes) == 6 and ds.info.format_version == "1.3"
    rows = ds.episodes.index.to_pylist()
    ep = _render(0, plans=(6, 3, 2))
    first = ds.episodes[0]
    assert (first["rgb"] == ep.frames).all()
    np.testing.assert_allclose(first["depth"], np.maximum(ep.depth, 0), atol=0.001)
    want = np.array([-1 if s is None else STATES.index(s) for s in ep.states])
    np.testing.assert_array_equal(first["state"], want)
    assert rows[0]["slip_onset_s"] == pytest.approx(ep.slip_onset_s)
    assert any(r["slip_onset_s"] is None for r in rows) == any(r["slip"] == "no" for r in rows)
    # samples: views of the takes, labelled by the frames they hold; the slip splits train
    slip = ds.view("slip")
    assert len(slip) and set(slip.index.column("state").to_pylist()) == set(STATES)
    kinds = {(k, s) for k, s, _ in episode_samples(ep)}
    ids = set(slip.index.column("sample_id").to_pylist())
    assert {f"episode-000000-s{s:06d}" for k, s in kinds if k == "slip"} <= ids
    for name in ("unseen_objects", "episode_unseen_objects"):
        assert name in ds.splits
    held = [json.loads((out / "meta" / "splits" / f"{n}.json").read_text())["params"]
            ["held_out_objects"] for n in ("unseen_objects", "episode_unseen_objects")]
    assert held[0] == held[1]
    test = ds.episodes.split("episode_unseen_objects", "test")
    assert {r["object"] for r in test.index.to_pylist()} == set(held[1])
    # the same options give the same bytes with one worker
    again = tmp_path / "again"
    simulate_episodes(again, opts, workers=1)
    for f in ("index/episodes.parquet", "index/frames.parquet", "index/slip.parquet",
              "meta/splits/unseen_objects.json"):
        assert (again / f).read_bytes() == (out / f).read_bytes(), f
    # an existing dataset is refused in one line
    with pytest.raises(VtsError, match=r"exists|already"):
        simulate_episodes(out, opts)
    # denser windows (stride 2, the default 4): the same takes and held-out objects, the slip splits
    # still written (whole takes in val), more samples
    dense = tmp_path / "dense"
    simulate_episodes(dense, dataclasses.replace(opts, sample_stride=2), workers=1)
    dd = vtsbench.load(dense)
    assert "unseen_objects" in dd.splits and len(dd.view("slip")) > 1.5 * len(slip)
    assert (dd.episodes[0]["rgb"] == first["rgb"]).all()
    assert json.loads((dense / "meta" / "splits" / "unseen_objects.json").read_text())[
        "params"]["held_out_objects"] == held[0]
    with pytest.raises(VtsError, match="--sample-stride"):
        simulate_episodes(tmp_path / "bad", dataclasses.replace(opts, sample_stride=0))
