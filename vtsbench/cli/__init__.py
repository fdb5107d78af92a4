"""The `vtsbench` command: the typer app, its commands registered in the order --help lists
them, and the console entry point `main`. Start-up imports only typer and the command modules
(typer and the standard library); every command imports its work when it runs."""

from __future__ import annotations

import sys
from typing import Annotated

import typer

from . import dataset, depth, episodes, evaluate, recipes, recordings, stream
from .help import install_lazily

install_lazily()

app = typer.Typer(
    name="vtsbench",
    help="Benchmark toolkit for visuo-tactile sensing: recordings -> calibrated RGB-D datasets "
         "-> loaders, baselines and scoring.",
    no_args_is_help=True,
    rich_markup_mode="rich",
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)


def _version(value: bool) -> None:
    """`vtsbench --version`: the installed package's version."""
    if value:
        from importlib.metadata import version

        typer.echo(f"vtsbench {version('vtsbench')}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[bool, typer.Option(
        "--version", callback=_version, is_eager=True,
        help="Print the version and exit.")] = False,
) -> None:
    """Options of `vtsbench` itself (the app's help text is the Typer's)."""


leaderboard_app = typer.Typer(help="Leaderboards in leaderboards/<dataset>/<split>/: add, "
                                   "render, rescore.", no_args_is_help=True)
leaderboard_app.command("add")(evaluate.leaderboard_add)
leaderboard_app.command("render")(evaluate.leaderboard_render)
leaderboard_app.command("rescore")(evaluate.leaderboard_rescore)

app.command("simulate")(recordings.simulate)
app.command("simulate-episodes")(episodes.simulate_episodes)
app.command("benchmark")(dataset.benchmark)
app.command("check")(recordings.check)
app.command("manifest")(recordings.manifest)
app.command("preview")(recordings.preview)
app.command("stats")(recordings.stats)
app.command("build")(dataset.build)
app.command("info")(dataset.info)
app.command("verify")(dataset.verify)
app.command("export-hf")(dataset.export_hf)
app.command("push")(dataset.push)
app.command("calibrate")(depth.calibrate)
app.command("depth")(depth.depth)
app.command("eval")(evaluate.eval_)
app.add_typer(leaderboard_app, name="leaderboard")
app.command("train")(recipes.train)
app.command("predict")(recipes.predict)
app.command("stream")(stream.stream)
app.command("collect")(recordings.collect)


def main() -> None:
    """Console entry point. A bad option or argument is one line on stderr naming it (exit 2),
    like every other user error, instead of click's multi-line usage box."""
    try:  # typer >= 0.2x carries its own click, whose exceptions derive from this
        from typer import TyperException as ClickError
    except ImportError:  # pragma: no cover - older typer on the click package
        from click import ClickException as ClickError

    try:
        rv = app(prog_name="vtsbench", standalone_mode=False)
    except typer.Abort:
        print("error: aborted", file=sys.stderr)
        sys.exit(1)
    except ClickError as e:
        ctx = getattr(e, "ctx", None)
        hint = f" (see `{ctx.command_path} --help`)" if ctx is not None else ""
        if e.format_message():  # empty after a group's help was shown for no command
            from ..errors import one_line

            print(f"error: {one_line(e.format_message())}{hint}", file=sys.stderr)
        sys.exit(getattr(e, "exit_code", 2))
    # a command's typer.Exit(code) comes back as its code; a command that returns is a success
    sys.exit(rv if isinstance(rv, int) else 0)
