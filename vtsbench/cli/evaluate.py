"""The eval stage's commands: eval and the leaderboard's add, render and rescore. Each parses its
options, calls the library (imported inside it) and prints the result."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .. import limits as lim
from .options import deprecated, str_option
from .run import console, run

ROOT = Annotated[Path, typer.Option("--root", help="Leaderboards folder.")]


def eval_(
    submission: Annotated[Path, typer.Argument(
        help="Predictions: CSV or parquet, or a stream submission (JSON lines).")],
    dataset: Annotated[str, str_option(limit=lim.MAX_PATH_TEXT, help=(
        "Dataset folder (made by vtsbench build), or a URL as vtsbench.load takes "
        "(file://, http(s)://, s3://...)."))],
    split: Annotated[str, str_option(limit=lim.MAX_SPLIT,
                                     help="Split scheme, e.g. unseen_objects or seen.")],
    part: Annotated[str, str_option(limit=lim.MAX_SPLIT,
                                    help="Part of the split to score.")] = "test",
    out: Annotated[Path | None, typer.Option(
        help="Write metrics.json, report.md and confusion-matrix PNGs here.")] = None,
    meta: Annotated[Path | None, typer.Option(
        help="Metadata JSON (default: SUBMISSION.meta.json beside it).")] = None,
    figures: Annotated[bool, typer.Option(help="Write the PNGs (with --out).")] = True,
) -> None:
    """Validate a submission, score it and print a short table; exit 2 listing every problem.

    Example: [bold]vtsbench eval preds.csv --dataset data/ds --split unseen_objects --out ev[/]
    """
    from ..evaluation.report import (
        SUMMARY_HEAD,
        direction_line,
        evaluate_submission,
        summary_rows,
        summary_title,
    )

    result, _, _ = run(evaluate_submission, submission, dataset, split, part, out=out, meta=meta,
                       figures=figures)
    if result.stream is not None:  # a stream submission (JSON lines of `vtsbench stream`)
        from ..evaluation.stream_result import stream_line

        typer.echo(f"{summary_title(result)}\n{stream_line(result.stream)}")
        if out is not None:
            typer.echo(f"wrote {out}/metrics.json and report.md")
        return
    print_rows(summary_title(result), SUMMARY_HEAD, summary_rows(result))
    line = direction_line(result)
    if line is not None:
        typer.echo(line)
    if out is not None:
        typer.echo(f"wrote {out}/metrics.json and report.md")


def print_rows(title: str, head: tuple[str, ...], rows: list[tuple[str, ...]]) -> None:
    """A titled table on stdout: the first and last columns left-aligned, the rest right."""
    from rich.markup import escape
    from rich.table import Table

    t = Table(title=escape(title), title_justify="left")
    for i, c in enumerate(head):
        t.add_column(c, justify="left" if i in (0, len(head) - 1) else "right")
    for r in rows:
        t.add_row(*(escape(x) for x in r))
    console().print(t)


def leaderboard_add(
    submission: Annotated[Path, typer.Argument(help="Predictions: CSV or parquet.")],
    dataset: Annotated[str, str_option(limit=lim.MAX_PATH_TEXT, help="Dataset folder or URL.")],
    split: Annotated[str, str_option(limit=lim.MAX_SPLIT, help="Split scheme.")],
    part: Annotated[str, str_option(limit=lim.MAX_SPLIT, help="Part of the split.")] = "test",
    meta: Annotated[Path | None, typer.Option(help="Metadata JSON.")] = None,
    root: ROOT = Path("leaderboards"),
    overwrite: Annotated[bool, typer.Option(
        "--overwrite", help="Replace the same submission's entry.")] = False,
    replace: Annotated[bool, typer.Option("--replace", hidden=True)] = False,
) -> None:
    """Score a submission and store it (predictions included) as a leaderboard entry."""
    from ..evaluation.leaderboard import add_and_render

    replace = overwrite or deprecated(replace, "--replace", "--overwrite")
    path = run(add_and_render, submission, dataset, split, part, root=root, meta=meta,
               replace=replace)
    typer.echo(f"added {path}; rendered {path.parent / 'leaderboard.md'}")


def leaderboard_render(root: ROOT = Path("leaderboards")) -> None:
    """Write leaderboard.md (summary with the paper's reference row, per-task detail) in every
    dataset/split folder and print them."""
    from ..evaluation.leaderboard import render

    for path, text in run(render, root).items():
        typer.echo(f"<!-- {path} -->\n{text}")


def leaderboard_rescore(
    dataset: Annotated[str, str_option(limit=lim.MAX_PATH_TEXT, help=(
        "The dataset the entries were scored on: folder or URL."))],
    root: ROOT = Path("leaderboards"),
    all_: Annotated[bool, typer.Option(
        "--all", help="Re-score entries of the current metric version too.")] = False,
    force: Annotated[bool, typer.Option("--force", hidden=True)] = False,
) -> None:
    """Re-score stored entries whose metric version is not the current one, then re-render."""
    from ..evaluation.leaderboard import rescore_and_render

    changed = run(rescore_and_render, root, dataset,
                  force=all_ or deprecated(force, "--force", "--all"))
    typer.echo(f"re-scored {len(changed)} entr{'y' if len(changed) == 1 else 'ies'}")
