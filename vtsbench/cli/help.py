"""`--help` that wraps to the terminal and never cuts: typer's rich help ellipsises a word
longer than its column (a path, an option's example) and keeps the docstrings' line breaks,
which break mid-sentence at any width but the source's. Two small adjustments of typer's
rich_utils (typer 0.2x), applied when help is first rendered (`install_lazily`): importing
rich_utils costs about 0.3 s (rich's markdown and columns), which a command that shows no help
need not pay; and of what rich_utils imports, the parts help never uses are left until used
(`DEFERRED`)."""

from __future__ import annotations

import re
from typing import Any

#: What typer's rich_utils imports at its top and our help never uses: rich's markdown (the help
#: is in rich markup) and its traceback (pretty exceptions are off). They are about a third of
#: `--help`'s imports (0.11 of 0.32 s, `python -X importtime`), so while rich_utils is imported
#: they are stand-ins that import the real class at its first use.
DEFERRED = (("rich.markdown", "Markdown"), ("rich.traceback", "Traceback"))


class _Deferred(type):
    """The class of a stand-in: calling it or reading an attribute imports the real class."""

    def real(cls) -> Any:
        import importlib

        return getattr(importlib.import_module(cls.__module__), cls.__name__)

    def __call__(cls, *args: Any, **kw: Any) -> Any:
        return cls.real()(*args, **kw)

    def __getattr__(cls, attr: str) -> Any:
        return getattr(cls.real(), attr)


def _import_rich_utils() -> Any:
    """typer.rich_utils, imported with DEFERRED's modules as stand-ins (those not yet imported):
    each holds a `_Deferred` class of the real one's name, and leaves sys.modules when the import
    is done, so a later import gets the real module."""
    import sys
    import types

    stubs = {}
    for module, name in DEFERRED:
        if module not in sys.modules:
            stubs[module] = types.ModuleType(module)
            setattr(stubs[module], name, _Deferred(name, (), {"__module__": module}))
    sys.modules.update(stubs)
    try:
        from typer import rich_utils
    finally:
        for module, stub in stubs.items():
            if sys.modules.get(module) is stub:
                del sys.modules[module]
    return rich_utils


def install() -> None:
    """Fold long words onto the next line instead of ending them with an ellipsis, and join a
    paragraph's lines so that the text wraps to the terminal's width."""
    try:
        from rich.columns import Columns
        from rich.table import Table
        from rich.text import Text

        rich_utils = _import_rich_utils()
    except ImportError:  # typer without rich: click's own help, which wraps and never cuts
        return
    if getattr(rich_utils, "_vtsbench_help", False):
        return

    class FoldTable(Table):
        """A table whose columns fold long words (rich's default is an ellipsis)."""

        def add_row(self, *renderables: Any, **kw: Any) -> None:
            while len(self.columns) < len(renderables):
                self.add_column(overflow="fold")
            for c in self.columns:
                c.overflow = "fold"
            for c, r in zip(self.columns, renderables, strict=False):  # names are never cut
                plain = getattr(r, "plain", r if isinstance(r, str) else "")
                if plain.startswith("-"):
                    c.min_width = max(c.min_width or 0, *(len(w) for w in plain.split()))
            super().add_row(*renderables, **kw)

    def fix_linebreaks(paragraphs: list[str], markup_mode: Any) -> str:
        return "\n\n".join(p if p.startswith("\b") else re.sub(r"\s*\n\s*", " ", p)
                           for p in paragraphs)

    def columns(items: list[Any], *args: Any, **kw: Any) -> Any:
        """An option's help, default and 'required' as one folding text (rich's Columns lays
        them out in a grid that ellipsises a long word)."""
        if not all(isinstance(i, Text) for i in items):
            return Columns(items, *args, **kw)
        out = Text(overflow="fold")
        for k, item in enumerate(items):
            if k:
                out.append(" ")
            out.append_text(item)
        return out

    make_command_help = rich_utils._make_command_help

    def command_help(*, help_text: str, markup_mode: Any) -> Any:
        """A command's line in its group's list: its first paragraph joined, as above."""
        return make_command_help(help_text=fix_linebreaks(help_text.split("\n\n"), markup_mode),
                                 markup_mode=markup_mode)

    rich_utils._make_command_help = command_help  # type: ignore[assignment]
    rich_utils.Columns = columns  # type: ignore[assignment]
    rich_utils.Table = FoldTable  # type: ignore[misc]
    rich_utils._fix_linebreaks = fix_linebreaks  # type: ignore[assignment]
    rich_utils._vtsbench_help = True  # type: ignore[attr-defined]


def install_lazily() -> None:
    """Make typer's help rendering (a group's and a command's `format_help`) call `install`
    first, so that rich_utils is imported only when help is shown."""
    from typer import core

    for cls in (core.TyperGroup, core.TyperCommand):
        orig = cls.format_help
        if getattr(orig, "_vtsbench_lazy", False):
            continue

        def format_help(self: Any, ctx: Any, formatter: Any, _orig: Any = orig) -> None:
            install()
            return _orig(self, ctx, formatter)

        format_help._vtsbench_lazy = True  # type: ignore[attr-defined]
        cls.format_help = format_help  # type: ignore[method-assign]
