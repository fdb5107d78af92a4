"""How the commands declare options and arguments: choices, bounded numbers and strings (the bound
stated in the help), deprecated spellings and --size; typer and the standard library only."""

from __future__ import annotations

from typing import Any

import typer

from .. import limits as lim


def choice(**kw: Any) -> Any:
    """An option whose annotation is a Literal of its values: --help lists them, the shell
    completes them, and any other value is a one-line usage error naming them (exit 2)."""
    return typer.Option(**kw)


def open_choice(*values: str, **kw: Any) -> Any:
    """An option with usual values (listed in --help and completed) that takes others too:
    a device is auto, cpu, cuda or cuda:N."""
    def complete(incomplete: str) -> list[str]:
        return [v for v in values if v.startswith(incomplete)]

    return typer.Option(metavar="[" + "|".join(values) + "|...]", autocompletion=complete,
                        **kw)


def deprecated(value: Any, old: str, new: str) -> Any:
    """The value of a hidden old spelling of an option, with a one-line note when it is used."""
    if value not in (None, False):
        typer.echo(f"note: {old} is deprecated; use {new}", err=True)
    return value


def finite(value: float | None) -> float | None:
    """Option callback: NaN and infinity are refused where a number is expected."""
    import math

    if value is not None and not math.isfinite(value):
        raise typer.BadParameter(f"expected a finite number, got {value}")
    return value


def max_chars(limit: int):
    """Option callback: a string (or each of a repeated option's strings) of at most LIMIT
    characters; the help text states the bound."""
    def check(value: Any) -> Any:
        for v in value if isinstance(value, (list, tuple)) else (value,):
            if v is not None and len(v) > limit:
                raise typer.BadParameter(f"{len(v)} characters; at most {limit}")
        return value

    return check


def str_option(*decls: str, help: str, limit: int = lim.MAX_NAME, **kw: Any) -> Any:
    """An option taking a string of at most LIMIT characters, the bound in its help."""
    return typer.Option(*decls, callback=max_chars(limit),
                        help=f"{help} At most {limit} characters.", **kw)


def str_argument(*, help: str, limit: int = lim.MAX_PATH_TEXT, **kw: Any) -> Any:
    """An argument taking a string of at most LIMIT characters, the bound in its help."""
    return typer.Argument(callback=max_chars(limit),
                          help=f"{help} At most {limit} characters.", **kw)


def finite_in(low: float | None, high: float | None):
    """Option callback: a finite number (NaN and infinity refused as by `finite`) from LOW to
    HIGH; a bound left None is the library's to check (its message names the file)."""
    def check(value: float | None) -> float | None:
        finite(value)
        if value is not None and ((low is not None and value < low)
                                  or (high is not None and value > high)):
            raise typer.BadParameter(f"expected a number {_bounds(low, high)}, got {value:g}")
        return value

    return check


def _bounds(low: float | None, high: float | None) -> str:
    if low is None:
        return f"of at most {high:g}"
    return f"from {low:g} to {high:g}" if high is not None else f"of at least {low:g}"


def number_option(*decls: str, help: str, low: float | None = None,
                  high: float | None = None, **kw: Any) -> Any:
    """An option taking a finite number within its bounds, stated in its help."""
    bound = _bounds(low, high).removeprefix("of ")
    return typer.Option(*decls, callback=finite_in(low, high),
                        help=f"{help} {bound[0].upper()}{bound[1:]}.", **kw)


def parse_size(text: str) -> tuple[int, int]:
    """--size HxW as (height, width); the bounds are the library's (simulate checks them)."""
    from ..errors import one_line

    try:
        h, w = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise typer.BadParameter(f"expected HxW such as 480x640, got {one_line(repr(text), 40)}"
                                 ) from None
    if h < 1 or w < 1:
        raise typer.BadParameter("height and width must be positive")
    return h, w
