"""The recipes stage's commands: train and predict. Each parses its options, calls one library
function (imported inside it) and prints the result."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .. import limits as lim
from .options import max_chars, open_choice, str_argument, str_option
from .run import run


def train(
    recipe: Annotated[str, str_argument(
        help="Recipe: a registered name (flow, timesformer, resnet...; a name wins over a file "
             "of that name in the working folder) or a file: NAME.py, ./NAME.")],
    dataset: Annotated[Path, typer.Option(help="Dataset folder.")],
    split: Annotated[str, str_option(limit=lim.MAX_SPLIT,
                                     help="Split scheme; trains on its train part.")],
    out: Annotated[Path, typer.Option(help="Output folder (checkpoints).")],
    config: Annotated[Path | None, typer.Option(
        help="JSON or TOML file overriding keys of the recipe's default config.")] = None,
    seed: Annotated[int, typer.Option(min=0, max=lim.MAX_SEED, help="Random seed.")] = 0,
    device: Annotated[str, open_choice(
        "auto", "cpu", "cuda", callback=max_chars(64),
        help="auto (CUDA when present), cpu, cuda, cuda:1... At most 64 characters.")] = "auto",
    resume: Annotated[bool, typer.Option(
        "--resume/--no-resume", help="Continue from the last checkpoint in --out.")] = True,
    quiet: Annotated[bool, typer.Option("--quiet", help="No progress bar.")] = False,
) -> None:
    """Train a recipe on a split's train part; prints the checkpoint path.

    Example: [bold]vtsbench train flow --dataset data/ds --split unseen_objects --out
    runs/flow[/]
    """
    from ..recipes.runs import train_run

    res = run(train_run, recipe, dataset, split, out, config=config, seed=seed, device=device,
              resume=resume, progress=not quiet)
    typer.echo(f"trained {res.recipe} on {split}/train: checkpoint {res.checkpoint}")


def predict(
    recipe: Annotated[str, str_argument(
        help="Recipe: a registered name (flow, timesformer, resnet...; a name wins over a file "
             "of that name in the working folder) or a file: NAME.py, ./NAME.")],
    checkpoint: Annotated[Path, typer.Argument(help="Checkpoint written by vtsbench train.")],
    dataset: Annotated[Path, typer.Option(help="Dataset folder.")],
    split: Annotated[str, str_option(limit=lim.MAX_SPLIT, help="Split scheme.")],
    out: Annotated[Path, typer.Option(help="Submission CSV to write (+ OUT.meta.json).")],
    part: Annotated[str, str_option(limit=lim.MAX_SPLIT,
                                    help="Part of the split to predict.")] = "test",
    device: Annotated[str, open_choice(
        "auto", "cpu", "cuda", callback=max_chars(64),
        help="auto, cpu, cuda, cuda:1... At most 64 characters.")] = "auto",
    method: Annotated[str | None, str_option(
        help="Method name in the metadata (default: the recipe's name).")] = None,
    seed: Annotated[int, typer.Option(min=0, max=lim.MAX_SEED,
                                      help="Training seed, for the metadata.")] = 0,
    stream: Annotated[bool, typer.Option(
        "--stream", help="A stream submission (JSON lines, one stream per episode of the split "
                         "part, e.g. --split episode_unseen_objects) instead of a CSV.")] = False,
    smoothing: Annotated[int, typer.Option(
        min=1, max=100, help="With --stream: calls in a row before the state changes.")] = 1,
) -> None:
    """Predict a split part with a trained recipe; writes a submission vtsbench eval accepts.

    Example: [bold]vtsbench predict flow runs/flow/checkpoint.safetensors --dataset
    data/ds --split unseen_objects --out flow.csv[/]; streams: [bold]vtsbench predict flow
    CKPT --dataset data/takes --split episode_unseen_objects --stream --smoothing 3 --out
    flow.jsonl[/]
    """
    if stream:
        from ..recipes.stream_submission import predict_streams

        sp = run(predict_streams, recipe, checkpoint, dataset, split, part, out,
                 smoothing=smoothing, device=device)
        typer.echo(f"wrote {sp.calls} calls on {sp.episodes} episodes to {sp.submission}")
        return
    from ..recipes.predict import predict_submission

    res = run(predict_submission, recipe, checkpoint, dataset, split, out, part=part,
              device=device, method=method, seed=seed)
    typer.echo(f"wrote {res.rows} rows for {res.samples} samples to {res.submission} and "
               f"{res.meta}")
