"""Running a command's library call: user errors (VtsError, OSError) as one line and exit 2,
Ctrl-C as exit 130, and the console and problem reports the commands print with."""

from __future__ import annotations

import os
from typing import Any

import typer


def fail(err: Exception, code: int = 2) -> None:
    """Print a user error as one line and exit (no traceback): control characters escaped and
    over-long values cut, whatever the error quotes (a path with a newline, a huge name)."""
    from ..errors import MAX_MESSAGE, MAX_PATH, one_line

    typer.echo(f"error: {one_line(err, MAX_MESSAGE + MAX_PATH + 2)}", err=True)
    raise typer.Exit(code)


def os_error(err: OSError) -> Exception:
    """An OSError as a one-line user error naming its file; a full disk met by a library's own
    write names none, so the output the command was writing (its --out, OUT or --root) is named."""
    import errno

    from ..errors import VtsError

    reason = err.strerror or str(err)
    if err.filename is not None:
        f = err.filename
        return VtsError(reason, os.fsdecode(f) if isinstance(f, bytes) else f)
    if err.errno in (errno.ENOSPC, errno.EFBIG, errno.EDQUOT, errno.EROFS, errno.EIO):
        try:  # typer >= 0.2x carries its own click
            from typer._click.globals import get_current_context
        except ImportError:  # pragma: no cover - older typer on the click package
            from click import get_current_context
        ctx = get_current_context(silent=True)
        params = ctx.params if ctx is not None else {}
        out = next((params[k] for k in ("out", "root") if params.get(k) is not None), None)
        return VtsError(f"cannot write ({reason})", out)
    return VtsError(reason)


def run(fn, *args, **kwargs):
    """Run a command body, turning user errors (VtsError) into a one-line message and exit 2."""
    from ..errors import VtsError

    try:
        return fn(*args, **kwargs)
    except VtsError as e:
        fail(e)
    except OSError as e:  # an output path that is a file or a folder, a name over 255 bytes...
        fail(os_error(e))
    except KeyboardInterrupt:
        typer.echo("interrupted: nothing was written under the output's final name", err=True)
        raise typer.Exit(130) from None


def console() -> Any:
    """A rich Console on stdout: the terminal's width, or 160 columns in a pipe or a log (no
    COLUMNS set), where rich would assume 80 and cut a table's names with an ellipsis."""
    from rich.console import Console

    out = Console(highlight=False)
    if not out.is_terminal and "COLUMNS" not in os.environ:
        out.width = 160
    return out


def report_problems(problems: list[str], warnings: list[str], summary: str) -> None:
    """Print warnings, problems (one line each) and a summary; exit 1 if there is a problem."""
    from rich.markup import escape

    out = console()
    for w in warnings:
        out.print(f"[yellow]warning[/] {escape(w)}", soft_wrap=True)
    for p in problems:
        out.print(f"[red]problem[/] {escape(p)}", soft_wrap=True)
    out.print(escape(summary))
    if problems:
        raise typer.Exit(1)
