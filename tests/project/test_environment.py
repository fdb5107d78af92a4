"""What made a figure: library versions in every submission, deterministic torch settings, and
the parts a recipe fits on."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from vtsbench.environment import deterministic, environment, library_versions
from vtsbench.errors import VtsError
from vtsbench.recipes import fit_view


def test_versions_without_importing_torch() -> None:
    code = ("import sys, json; from vtsbench.environment import environment; "
            "e = environment('cpu'); print(json.dumps([e, 'torch' in sys.modules]))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    env, torch_loaded = json.loads(out)
    assert not torch_loaded and "torch_threads" not in env and env["device"] == "cpu"
    assert {"python", "numpy", "torch", "vtsbench"} <= set(env["libraries"])
    assert library_versions()["numpy"] == __import__("numpy").__version__


def test_deterministic_pins_threads() -> None:
    import torch

    before = torch.get_num_threads()
    try:
        deterministic(1)
        assert torch.get_num_threads() == 1 and torch.are_deterministic_algorithms_enabled()
        assert environment()["torch_threads"] == 1
    finally:
        torch.use_deterministic_algorithms(False)
        torch.set_num_threads(before)


def test_fit_view_unions_parts_and_refuses_test(vts_dataset: Path) -> None:
    import vtsbench

    ds = vtsbench.load(vts_dataset)
    train, val = (ds.split("unseen_objects", p) for p in ("train", "val"))
    both = fit_view(vts_dataset, "unseen_objects", ["train", "val"])
    assert sorted(both.ids) == sorted([*train.ids, *val.ids])
    assert fit_view(vts_dataset, "unseen_objects").ids == train.ids
    with pytest.raises(VtsError, match="test"):
        fit_view(vts_dataset, "unseen_objects", ["train", "test"])
    with pytest.raises(VtsError, match="at least one"):
        fit_view(vts_dataset, "unseen_objects", [])
