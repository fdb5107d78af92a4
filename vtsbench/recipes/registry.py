"""Finding a recipe by name or file: `load_recipe` (entry points of the group
`vtsbench.recipes`, the built-in recipes, or a .py file defining RECIPE), and the one-line
error of a recipe whose packages are not installed (`guarded`)."""

from __future__ import annotations

import importlib
import importlib.util
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from vtsbench.errors import VtsError

from .base import as_recipe

ENTRY_POINT_GROUP = "vtsbench.recipes"
#: The package of the built-in recipes, looked up by name when the installed metadata
#: predates one.
BUILTIN_PACKAGE = "vtsbench.recipes.builtin"


def _from_file(path: Path) -> Any:
    if not path.is_file():
        raise VtsError("recipe file not found", path)
    mod_name = f"vtsbench_recipe_{path.stem}_{abs(hash(str(path.resolve()))) & 0xFFFFFFFF:x}"
    from importlib.machinery import SourceFileLoader

    # the loader named: a recipe file without the .py suffix (./flow) is Python source too
    spec = importlib.util.spec_from_file_location(mod_name, path,
                                                  loader=SourceFileLoader(mod_name, str(path)))
    if spec is None or spec.loader is None:
        raise VtsError("cannot import the recipe file", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[mod_name] = module
    try:
        spec.loader.exec_module(module)
    except ModuleNotFoundError as e:
        sys.modules.pop(mod_name, None)
        raise VtsError(_needs(e), path) from None
    except Exception:
        sys.modules.pop(mod_name, None)
        raise
    if not hasattr(module, "RECIPE"):
        raise VtsError("the recipe file defines no RECIPE", path)
    return as_recipe(module.RECIPE, str(path))


def registered() -> dict[str, Any]:
    """The entry points of the group `vtsbench.recipes`, by name."""
    from importlib.metadata import entry_points

    return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}


def _builtin_file(name: str) -> Path | None:
    """vtsbench/recipes/builtin/NAME.py (when the installed metadata predates it)."""
    path = Path(__file__).resolve().parent / "builtin" / f"{name}.py"
    return path if path.is_file() else None


def _needs(e: ModuleNotFoundError) -> str:
    """The one-line reason of a recipe that imports a package that is not installed."""
    extra = " (pip install 'vtsbench[torch]')" if (e.name or "").split(".")[0] in (
        "torch", "torchvision", "transformers") else ""
    return f"the recipe needs the Python package {e.name!r}, which is not installed{extra}"


def guarded(fn: Callable[..., Any], where: str) -> Callable[..., Any]:
    """FN, with a package it imports only when called (a recipe's torch, transformers) that is
    not installed made one line naming WHERE and the install command."""
    def call(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except ModuleNotFoundError as e:
            raise VtsError(_needs(e), where) from None

    return call


def load_recipe(name_or_path: str | Path) -> Any:
    """A recipe from a .py file defining RECIPE, or by its registered name.

    A registered or built-in name always means that recipe, even when a file of that name is in
    the working folder; a file is given by a name ending in .py or a path with a folder
    (./flow); any other existing file is read as a recipe file too."""
    text = str(name_or_path)
    if text.endswith(".py") or "/" in text or (os.sep in text) or (
            os.altsep is not None and os.altsep in text):
        return _from_file(Path(text))
    eps = registered()
    if text in eps:
        try:
            return as_recipe(eps[text].load(), f"entry point {text}")
        except ModuleNotFoundError as e:
            if not eps[text].module.startswith(e.name or "\0"):  # else stale metadata: below
                raise VtsError(_needs(e), f"recipe {text}") from None
    module = None
    if text.isidentifier():  # a module name: not "", ".x" or "a-b"
        try:
            module = importlib.import_module(f"{BUILTIN_PACKAGE}.{text}")
        except ModuleNotFoundError as e:
            if e.name and not e.name.startswith(BUILTIN_PACKAGE):
                raise VtsError(_needs(e), f"recipe {text}") from None
    if module is not None and hasattr(module, "RECIPE"):
        return as_recipe(module.RECIPE, f"{BUILTIN_PACKAGE}.{text}")
    path = _builtin_file(text) if text.isidentifier() else None
    if path is not None:
        return _from_file(path)
    if text and Path(text).is_file():
        return _from_file(Path(text))
    known = ", ".join(sorted(eps)) or "none"
    raise VtsError(f"unknown recipe {text!r} (registered: {known}; or give a path to a .py file)")
