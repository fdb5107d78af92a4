"""docs/cli.md from the command line itself: every command, argument and option, walked from
the click tree typer builds, so the page cannot drift from the code (a test compares them).

    python -m vtsbench.cli.doc docs/cli.md   (or its older name, python -m vtsbench.cli_doc)
"""

from __future__ import annotations

import re
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

HEAD = """\
# Command line reference

Generated from the command line by `python -m vtsbench.cli.doc docs/cli.md`; a test fails when
this page is out of date. `vtsbench COMMAND -h` (or `--help`) shows the same, with examples.

- `vtsbench --version` prints the installed version.
- `-h` is `--help` on every command.
- Shell completion (commands, options, paths and the choices listed below):
  `vtsbench --install-completion` installs it for the current shell;
  `vtsbench --show-completion bash > ~/.vtsbench-complete.bash` (or `zsh`, `fish`,
  `powershell`) writes the script to source yourself.
- A choice such as `[dct|dst|masked]` lists the accepted values, and any other value is a
  one-line usage error (exit 2); `[auto|cpu|cuda|...]` also takes others (`cuda:1`). An
  option shown without a
  value is a flag (`--quiet`), and only options where both forms mean something have a
  `--no-` form (`--no-zarr`, `--no-resume`, `--no-figures`).
"""

#: Ideas that several commands share, and the one name each goes by (arguments in capitals).
IDEAS: dict[str, tuple[str, ...]] = {
    "the data a command works on (its subject)": ("FOLDER", "RECORDINGS", "DATASET",
                                                  "SUBMISSION"),
    "the data folder a command creates": ("OUT",),
    "any other output (a file, a report, a run)": ("--out",),
    "a dataset read for reference": ("--dataset",),
    "replace what is there": ("--overwrite",),
    "ball radius in mm": ("--ball-radius-mm",),
    "the dataset's version": ("--dataset-version",),
    "the program's version": ("--version",),
    "no progress bar": ("--quiet",),
}

KNOWN = """\
The conventions behind the table:

- Positional arguments are the command's subject: the recordings, dataset or submission it
  reads (`check FOLDER`, `info DATASET`, `eval SUBMISSION`), and the data folder it creates
  (`simulate OUT`, `collect OUT`, `build RECORDINGS OUT`). `info` and `verify` take a path or
  any URL `vtsbench.load` takes.
- Every other output is `--out` (a calibration file, a contact sheet, depth maps, an evaluation
  report, a training run, a submission).
- A dataset read for reference by a command about something else (a submission, a recipe) is
  `--dataset`.
- Replacing an existing output is always `--overwrite`. Old spellings still work, hidden, with a
  one-line deprecation note: `manifest --force`, `leaderboard add --replace`, `leaderboard
  rescore --force` (now `--all`: re-score current entries too), `collect --ball-radius`,
  `build --version` (now `--dataset-version`).
- Units are part of a name where a value has one (`--ball-radius-mm`, `--mm-per-px`,
  `--shard-mb`).
"""


def _flat(text: str | None) -> str:
    """One line of markdown-safe text: rich markup removed, whitespace joined, pipes escaped."""
    text = re.sub(r"\[/?(bold|red|yellow|green)?\]", "", text or "")
    return re.sub(r"\s+", " ", text).strip().replace("|", "\\|")


def commands(cmd: Any, path: tuple[str, ...] = ()) -> Iterator[tuple[tuple[str, ...], Any]]:
    """Every (path, command) under a click command, depth first in name order."""
    yield path, cmd
    for name, sub in sorted(getattr(cmd, "commands", {}).items()):
        yield from commands(sub, (*path, name))


def _names(param: Any) -> str:
    if param.param_type_name == "argument":
        return (param.name or "").upper()
    names = [*param.opts, *param.secondary_opts]
    return " / ".join(sorted(names, key=lambda n: (n.startswith("--no-"), len(n))))


def _value(param: Any) -> str:
    """A flag, the choices, or the value's type with its range."""
    import typing

    if getattr(param, "is_flag", False) and not param.secondary_opts:
        return "flag"
    ann = getattr(getattr(param, "type_descriptor", None), "annotation", str)
    choices = _literal(ann)
    if choices:  # a strict choice
        return "[" + "|".join(choices) + "]"
    if param.metavar:
        return param.metavar
    many = typing.get_origin(ann) is list
    if many:
        ann = typing.get_args(ann)[0]
    text = _TYPES.get(getattr(ann, "__name__", ""), "text")
    lo, hi = getattr(param, "min", None), getattr(param, "max", None)
    if lo is not None or hi is not None:
        text += f" {'' if lo is None else lo}..{'' if hi is None else hi}"
    return text + (", repeatable" if many else "")


def _literal(ann: Any) -> list[str]:
    """The values of a Literal annotation (also inside `Literal[...] | None`), else []."""
    import typing

    if typing.get_origin(ann) is typing.Literal:
        return [str(v) for v in typing.get_args(ann)]
    for arg in typing.get_args(ann):
        if typing.get_origin(arg) is typing.Literal:
            return _literal(arg)
    return []


_TYPES = {"Path": "path", "str": "text", "int": "integer", "float": "number", "bool": "bool"}


def _default(param: Any) -> str:
    if param.required:
        return "required"
    d = param.default
    if d is None or callable(d) or (getattr(param, "is_flag", False)
                                    and not param.secondary_opts and d is False):
        return ""
    if isinstance(d, bool):
        return (param.opts if d else param.secondary_opts)[0]
    if isinstance(d, (list, tuple)):
        return ""
    return str(d)


def _row(*cells: str) -> str:
    return "| " + " | ".join(re.sub(r"(?<!\\)\|", r"\\|", c) for c in cells) + " |"


def markdown() -> str:
    """The whole page."""
    import typer

    from . import app

    root = typer.main.get_command(app)
    out = [HEAD]
    used: dict[str, list[str]] = {}
    for path, cmd in commands(root):
        title = " ".join(("vtsbench", *path))
        if getattr(cmd, "commands", None) and path:
            out.append(f"## `{title}`\n\n{_flat(cmd.help).split('. ')[0]}.\n")
            continue
        out.append(f"## `{title}`\n")
        if cmd.help and path:
            out.append(_flat(cmd.help.split("\n\n")[0]) + "\n")
        out.append(_row("argument / option", "value", "default", "help"))
        out.append("|---|---|---|---|")
        for p in cmd.params:
            if getattr(p, "hidden", False):
                continue
            name = _names(p)
            for n in name.split(" / "):
                used.setdefault(n, []).append(" ".join(path) or "vtsbench")
            out.append(_row(f"`{name}`", f"`{_value(p)}`" if _value(p) else "",
                            f"`{_default(p)}`" if _default(p) else "",
                            _flat(getattr(p, "help", None) or "")))
        out.append(_row("`-h` / `--help`", "`flag`", "", "Show the help and exit."))
        out.append("")
    out.append("## One name per idea\n")
    out.append("The name each shared idea goes by, and the commands using it:\n")
    out.append(_row("idea", "name", "commands"))
    out.append("|---|---|---|")
    for idea, names in IDEAS.items():
        for n in names:
            if n in used:
                out.append(_row(idea, f"`{n}`", ", ".join(f"`{c}`" for c in used[n])))
    out.append("")
    out.append(KNOWN)
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    """Write the page to the path given (default docs/cli.md)."""
    args = sys.argv[1:] if argv is None else argv
    path = Path(args[0] if args else "docs/cli.md")
    from ..atomic import write_text_atomic

    write_text_atomic(path, markdown())
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
