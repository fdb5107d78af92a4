"""Imports point down the data flow: a stage imports earlier stages, never later ones.

Inside `vtsbench.dataset` the order is format <- splits <- read <- build <- tools (readers never
import writers). Unlike the circle test, imports under `if TYPE_CHECKING:` count here too: an
annotation that needs a later stage's type says the type lives in the wrong module.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import vtsbench

ROOT = Path(vtsbench.__file__).parent

#: The dataset package's stages, earliest first.
DATASET_STAGES = ("format", "splits", "read", "build", "tools")


def module_name(path: Path, root: Path) -> str:
    """The dotted name of a source file under the package root."""
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def all_imports(tree: ast.Module, module: str, is_package: bool) -> set[str]:
    """Every dotted name any `import` in the tree may load, TYPE_CHECKING blocks included."""
    package = module if is_package else module.rpartition(".")[0]
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                src = ".".join(base + ([node.module] if node.module else []))
            else:
                src = node.module or ""
            out.add(src)
            out.update(f"{src}.{a.name}" for a in node.names)
    return out


def graph(root: Path) -> dict[str, set[str]]:
    """Module -> the package's modules it imports (any import, any place)."""
    files = {module_name(p, root): p for p in sorted(root.rglob("*.py"))}
    out = {}
    for name, path in files.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        names = all_imports(tree, name, path.name == "__init__.py")
        out[name] = {n for n in names if n in files and n != name}
    return out


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
