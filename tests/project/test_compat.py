"""Old import paths that users may hold keep working after the move to stages.

Each path below was documented before the package was laid out by stage; its names must still
import, and be the very objects of their new home (a copy would drift)."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

OLD = [
    ("vtsbench.dataset.loader", "load", "vtsbench.dataset.read.loader"),
    ("vtsbench.dataset.schema", "Sample", "vtsbench.dataset.format.records"),
    ("vtsbench.dataset.schema", "load_info", "vtsbench.dataset.format.info"),
    ("vtsbench.dataset.store", "open_group", "vtsbench.dataset.read.store"),
    ("vtsbench.dataset.store", "encode_shard", "vtsbench.dataset.build.store"),
    ("vtsbench.dataset.verify", "chunk_of_byte", "vtsbench.dataset.tools.verify"),
    ("vtsbench.dataset.hub", "export_hf", "vtsbench.dataset.tools.hub"),
    ("vtsbench.dataset.depthmaps", "DepthMaker", "vtsbench.depth.depthmaps"),
    ("vtsbench.dataset.splits", "make_splits", "vtsbench.dataset.splits.schemes"),
    ("vtsbench.dataset.build", "build", "vtsbench.dataset.build.pipeline"),
    ("vtsbench.models.contact_crop", "contact_crop", "vtsbench.transforms.contact_crop"),
    ("vtsbench.models.motion", "shift_field", "vtsbench.transforms.motion"),
    ("vtsbench.depth.calibration", "taxim_recordings", "vtsbench.recordings.taxim"),
    ("vtsbench.recipes_builtin.flow", "RECIPE", "vtsbench.recipes.builtin.flow"),
    ("vtsbench.recipes_builtin.resnet", "RECIPE", "vtsbench.recipes.builtin.resnet"),
    ("vtsbench.recipes_builtin.timesformer", "RECIPE", "vtsbench.recipes.builtin.timesformer"),
]


@pytest.mark.parametrize("old, name, new", OLD, ids=[f"{o}.{n}" for o, n, _ in OLD])
def test_an_old_path_gives_the_new_object(old: str, name: str, new: str) -> None:
    if "resnet" in old or "timesformer" in old:
        pytest.importorskip("torch")
    assert getattr(importlib.import_module(old), name) is \
        getattr(importlib.import_module(new), name)


def test_the_old_torch_adapter_path() -> None:
    pytest.importorskip("torch")
    from vtsbench.dataset.read.torch_dataset import HorizontalFlip
    from vtsbench.dataset.torch_dataset import HorizontalFlip as Old

    assert Old is HorizontalFlip


def test_the_old_doc_generator_runs(tmp_path) -> None:
    out = tmp_path / "cli.md"
    subprocess.run([sys.executable, "-m", "vtsbench.cli_doc", str(out)], check=True,
                   capture_output=True)
    assert out.read_text().startswith("# ")
