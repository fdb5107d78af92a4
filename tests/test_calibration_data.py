"""Shared data of the calibration tests: small simulated presses, made once per test process.

Holds no tests. Each calibration test module wraps these in its own fixtures; the cache below
makes them share one simulated folder (and one fitted calibration per method) per process.
"""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path
from typing import Any

import pytest

from vtsbench.recordings.manifest import load_manifest, save_manifest

#: 120x160 presses at 0.06 mm/px (contact radii 18-35 px); a seed no other test uses.
SEED, N_PRESSES, SIZE, MM_PER_PX = 11, 10, (120, 160), 0.06
#: Fast settings per method for the tests (the defaults are for real calibrations).
FAST = {"lut": {"bins": 24, "cells": 2}, "poly": {}, "mlp": {"epochs": 12}}

_cache: dict[Any, Any] = {}


def sim_folder(factory: pytest.TempPathFactory) -> Path:
    """The simulated presses folder (read-only by convention: copy before changing)."""
    if "sim" not in _cache:
        from vtsbench.sim.simulate import simulate

        root = factory.mktemp("calibration") / "sim"
        # generator 1's clean sensor: these presses measure the mapping and the circle
        # detection themselves, with thresholds set on it; generator 2's weaker imprint, gel
        # pattern and compression cost 18-42 % more depth error (docs/simulator.md)
        simulate(root, seed=SEED, n_static=0, n_sequences=0, n_presses=N_PRESSES, size=SIZE,
                 mm_per_px=MM_PER_PX, generator=1)
        _cache["sim"] = root
    return _cache["sim"]


def fitted(factory: pytest.TempPathFactory, method: str) -> Any:
    """A CalibrationRun of the method on the simulated presses (2 held out, seed 1)."""
    if method == "mlp":
        pytest.importorskip("torch")
    if method not in _cache:
        from vtsbench.depth.calibration import calibrate

        _cache[method] = calibrate(sim_folder(factory), method=method, holdout=2, seed=1,
                                   options=FAST[method], device=None)
    return _cache[method]


def copy_folder(src: Path, dst: Path, **changes: Any) -> Path:
    """Copy a recordings folder; `edit(entries, sessions)` in changes rewrites its manifest."""
    shutil.copytree(src, dst)
    edit = changes.get("edit")
    if edit is not None:
        m = load_manifest(dst)
        m.entries, m.sessions = edit(list(m.entries), list(m.sessions))
        save_manifest(dst, m)
    return dst


def replace(obj: Any, **kw: Any) -> Any:
    """dataclasses.replace, short."""
    return dataclasses.replace(obj, **kw)


def digit_recordings(out: Path) -> Path:
    """A recordings folder (manifest only, written to out) for the real DIGIT presses with
    their labelled circles, made by `vtsbench manifest` as a user would; skips when absent."""
    from typer.testing import CliRunner

    from tests.conftest import real_dir
    from vtsbench.cli import app

    src = real_dir("digit_ball_6mm")
    res = CliRunner().invoke(app, ["manifest", str(src), "--pattern", "{name}.png", "--kind",
                                   "press", "--ball-radius-mm", "3", "--circles",
                                   str(src / "sphere.csv"), "--out", str(out)])
    assert res.exit_code == 0, res.output
    return out
