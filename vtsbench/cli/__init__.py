"""The `vtsbench` command: the typer app, its commands registered in the order --help lists
them, and the console entry point `main`. Start-up imports only typer and the command modules
(typer and the standard library); a command's click parameters are built when it is called
(`lazy.LazyTyper`), and every command imports its work when it runs."""

from __future__ import annotations

import sys
from typing import Annotated

import typer

from . import dataset, depth, episodes, evaluate, recipes, recordings, stream
from .help import install_lazily
from .lazy import LazyTyper

install_lazily()

app = LazyTyper(
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


leaderboard_app = LazyTyper(help="Leaderboards in leaderboards/<dataset>/<split>/: add, "
                             "render, rescore.", no_args_is_help=True)
leaderboard_app.lazy_command("add", evaluate.leaderboard_add)
leaderboard_app.lazy_command("render", evaluate.leaderboard_render)
leaderboard_app.lazy_command("rescore", evaluate.leaderboard_rescore)

app.lazy_command("simulate", recordings.simulate)
app.lazy_command("simulate-episodes", episodes.simulate_episodes)
app.lazy_command("benchmark", dataset.benchmark)
app.lazy_command("check", recordings.check)
app.lazy_command("manifest", recordings.manifest)
app.lazy_command("import-presses", recordings.import_presses)
app.lazy_command("preview", recordings.preview)
app.lazy_command("stats", recordings.stats)
app.lazy_command("build", dataset.build)
app.lazy_command("info", dataset.info)
app.lazy_command("verify", dataset.verify)
app.lazy_command("export-hf", dataset.export_hf)
app.lazy_command("push", dataset.push)
app.lazy_command("calibrate", depth.calibrate)
app.lazy_command("depth", depth.depth)
app.lazy_command("eval", evaluate.eval_)
app.lazy_command("train", recipes.train)
app.lazy_command("predict", recipes.predict)
app.lazy_command("stream", stream.stream)
app.lazy_command("collect", recordings.collect)
app.lazy_typer("leaderboard", leaderboard_app)


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
