"""Imports point down the data flow: a stage imports earlier stages, never later ones.

Inside `vtsbench.dataset` the order is format <- splits <- read <- build <- tools (readers never
import writers). Unlike the circle test, imports under `if TYPE_CHECKING:` count here too: an
annotation that needs a later stage's type says the type lives in the wrong module.
"""

from __future__ import annotations

from pathlib import Path

import pytest

import vtsbench
from tests.fixtures.import_graph import import_graph, module_name

ROOT = Path(vtsbench.__file__).parent

#: The dataset package's stages, earliest first.
DATASET_STAGES = ("format", "splits", "read", "build", "tools")


def graph(root: Path) -> dict[str, set[str]]:
    """Module -> the package's modules it imports (any import, any place)."""
    return import_graph(root, type_checking=True)


def stage_of(module: str, top: str) -> int | None:
    """The rank of a `top.dataset.<stage>...` module, None outside the staged packages."""
    parts = module.split(".")
    if len(parts) >= 3 and parts[:2] == [top, "dataset"] and parts[2] in DATASET_STAGES:
        return DATASET_STAGES.index(parts[2])
    return None


def upward_imports(g: dict[str, set[str]], top: str) -> list[str]:
    """Every import from an earlier dataset stage into a later one, as 'a -> b'."""
    bad = []
    for mod, deps in sorted(g.items()):
        own = stage_of(mod, top)
        if own is None:
            continue
        for dep in sorted(deps):
            rank = stage_of(dep, top)
            if rank is not None and rank > own:
                bad.append(f"{mod} -> {dep}")
    return bad


def test_dataset_stages_exist_and_hold_modules() -> None:
    g = graph(ROOT)
    for stage in DATASET_STAGES:
        members = [m for m in g if m.startswith(f"vtsbench.dataset.{stage}.")]
        assert members, f"no modules in vtsbench.dataset.{stage}"


def test_dataset_imports_point_down() -> None:
    bad = upward_imports(graph(ROOT), "vtsbench")
    assert not bad, "imports from an earlier stage into a later one: " + "; ".join(bad)


def test_dataset_modules_are_small() -> None:
    big = {m: n for m, n in ((module_name(p, ROOT), len(p.read_text().splitlines()))
                             for p in (ROOT / "dataset").rglob("*.py")) if n > 520}
    assert not big, f"modules over about 500 lines: {big}"


@pytest.mark.parametrize("source, expect", [
    ("from ..build.plan import Plan\n", ["pkg.dataset.read.x -> pkg.dataset.build.plan"]),
    ("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from ..tools import info\n",
     ["pkg.dataset.read.x -> pkg.dataset.tools", "pkg.dataset.read.x -> pkg.dataset.tools.info"]),
    ("def f():\n    from pkg.dataset.build import plan\n",
     ["pkg.dataset.read.x -> pkg.dataset.build", "pkg.dataset.read.x -> pkg.dataset.build.plan"]),
    ("from ..format import layout\nfrom . import y\n", []),
])
def test_an_upward_import_is_reported(tmp_path: Path, source: str, expect: list[str]) -> None:
    pkg = tmp_path / "pkg"
    for sub in ("", "dataset", "dataset/format", "dataset/read", "dataset/build",
                "dataset/tools"):
        (pkg / sub).mkdir(parents=True, exist_ok=True)
        (pkg / sub / "__init__.py").write_text("")
    for mod in ("format/layout", "read/y", "build/plan", "tools/info"):
        (pkg / "dataset" / f"{mod}.py").write_text("x = 1\n")
    (pkg / "dataset" / "read" / "x.py").write_text(source)
    assert upward_imports(graph(pkg), "pkg") == expect


#: The package's stages in data-flow order; a module may import its own stage or earlier ones.
PACKAGE_STAGES: tuple[tuple[str, ...], ...] = (
    # "" is the package itself: importing it loads nothing (`vtsbench.load` is imported lazily)
    ("", "errors", "atomic", "jsonio", "labels", "limits", "progress", "figures", "environment"),
    ("recordings",),
    ("depth",),
    ("sim", "stats"),
    ("dataset.format",),
    ("dataset.splits",),
    ("dataset.read",),
    ("dataset.build",),
    ("dataset.tools", "sim.benchmark",  # benchmark: simulate, calibrate and build in one run
     "sim.episode_dataset"),  # simulated takes written through vtsbench.create
    ("transforms",),
    ("models",),
    ("recipes", "training"),
    ("evaluation",),
    ("cli", "__main__"),
)

#: Old import paths kept for users (tests/test_compat.py): nothing inside the package uses them.
SHIMS = ("dataset.loader", "dataset.schema", "dataset.store", "dataset.verify", "dataset.hub",
         "dataset.torch_dataset", "dataset.depthmaps", "models.contact_crop", "models.motion",
         "recipes_builtin", "cli_doc")


def _part(module: str, top: str) -> str:
    return module[len(top) + 1:] if module.startswith(top + ".") else ""


def package_rank(module: str, top: str) -> int | None:
    """The stage of a module (None for a shim or the `dataset` package's own facade)."""
    rest = _part(module, top)
    if rest == "dataset" or any(rest == s or rest.startswith(s + ".") for s in SHIMS):
        return None
    found = [(len(name), rank) for rank, names in enumerate(PACKAGE_STAGES) for name in names
             if rest == name or (name and rest.startswith(name + "."))]
    if not found:
        raise AssertionError(f"{module} is in no stage: add it to PACKAGE_STAGES")
    return max(found)[1]  # the longest name wins: sim.benchmark over sim


def package_upward(g: dict[str, set[str]], top: str) -> list[str]:
    """Every import from an earlier stage into a later one, and every use of a shim."""
    bad = []
    for mod, deps in sorted(g.items()):
        own = package_rank(mod, top)
        if own is None or mod == top:  # the package's own facade offers `load` lazily
            continue
        for dep in sorted(deps):
            rank = package_rank(dep, top)
            if rank is None and _part(dep, top) != "dataset":
                bad.append(f"{mod} -> {dep} (an old path kept for users)")
            elif rank is not None and rank > own:
                bad.append(f"{mod} -> {dep}")
    return bad


def test_package_imports_point_down_the_data_flow() -> None:
    bad = package_upward(graph(ROOT), "vtsbench")
    assert not bad, "imports against the data flow: " + "; ".join(bad)


def test_a_package_upward_import_is_reported(tmp_path: Path) -> None:
    pkg = tmp_path / "pkg"
    for sub in ("", "depth", "evaluation", "dataset", "dataset/read"):
        (pkg / sub).mkdir(parents=True, exist_ok=True)
        (pkg / sub / "__init__.py").write_text("")
    (pkg / "evaluation" / "score.py").write_text("from ..depth import fit\n")
    (pkg / "dataset" / "loader.py").write_text("from .read.loader import load\n")
    (pkg / "dataset" / "read" / "loader.py").write_text("load = 1\n")
    (pkg / "depth" / "fit.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from ..evaluation import score\n"
        "def f():\n    from ..dataset.loader import load\n")
    assert package_upward(graph(pkg), "pkg") == [
        "pkg.depth.fit -> pkg.dataset.loader (an old path kept for users)",
        "pkg.depth.fit -> pkg.evaluation", "pkg.depth.fit -> pkg.evaluation.score"]
