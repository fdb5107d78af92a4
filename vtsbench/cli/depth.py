"""The calibration and depth stage's commands: calibrate and depth. Each parses its options,
calls one library function (imported inside it) and prints the result."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import typer

from .. import limits as lim
from .options import choice, number_option, str_argument, str_option
from .run import run


def calibrate(
    recordings: Annotated[Path, typer.Argument(help="Recordings folder with ball presses.")],
    out: Annotated[Path, typer.Option("--out", help="Calibration file to write (.safetensors).")],
    method: Annotated[Literal["lut", "poly", "mlp"], choice(
        help="lut (fast lookup), poly (polynomial) or mlp (small network, needs torch).")
    ] = "poly",
    holdout: Annotated[int | None, typer.Option(
        min=0, max=lim.MAX_COUNT,
        help="Presses kept out of training and scored (default: a fifth).")] = None,
    seed: Annotated[int, typer.Option(
        min=0, max=lim.MAX_SEED, help="Seed of the hold-out choice, sampling, mlp.")] = 0,
    mm_per_px: Annotated[float | None, number_option(
        high=100.0,
        help="Scale in mm per pixel (default: from the recordings).")] = None,
    background: Annotated[Path | None, typer.Option(
        help="No-contact image (default: the sessions' backgrounds); one that shows a contact "
             "of its own, or has its colour channels in the other order from the presses', "
             "is named in a warning.")] = None,
    estimate_background: Annotated[bool, typer.Option(
        "--estimate-background",
        help="Use the per-pixel median of the press frames as the background (for sets "
             "recorded without one; warned where half or more of the presses touch one "
             "spot).")] = False,
    report: Annotated[Path | None, typer.Option(
        help="Report folder (default: FILE.report beside the calibration).")] = None,
    solver: Annotated[Literal["dct", "dst", "masked"], choice(
        help="Poisson solver scoring the held-out presses: dct, dst or masked.")] = "dct",
    device: Annotated[Literal["auto", "cpu", "cuda"], choice(
        help="mlp training device: auto (CUDA when present), cpu or cuda.")] = "auto",
    bins: Annotated[int | None, typer.Option(
        min=2, max=256,
        help="lut: colour bins per channel (32); bins^3 x cells^2 at most 2^26.")] = None,
    cells: Annotated[int | None, typer.Option(
        min=1, max=64, help="lut: spatial cells per side (2).")] = None,
    degree: Annotated[int | None, typer.Option(
        min=1, max=8, help="poly: colour degree (3).")] = None,
    pos_degree: Annotated[int | None, typer.Option(
        min=0, max=4, help="poly, mlp: degree of the position polynomial (2).")] = None,
    width: Annotated[int | None, typer.Option(
        min=1, max=4096, help="mlp: units per hidden layer (32).")] = None,
    depth: Annotated[int | None, typer.Option(min=1, max=32, help="mlp: hidden layers (3).")
                     ] = None,
    epochs: Annotated[int | None, typer.Option(
        min=1, max=100_000, help="mlp: training epochs (40).")] = None,
    circles: Annotated[Literal["label", "detect"], choice(
        help="label: use labelled circles, detect the others; detect: detect every circle "
             "(labels only compared, in report.json).")] = "label",
    markers: Annotated[Literal["auto", "off"], choice(
        help="auto: a marker grid found in the background is divided out of the colour "
             "difference and blurred there, its dark cores left out of the fit and filled "
             "before integration; off: never.")] = "auto",
    rim_cv: Annotated[bool, typer.Option(
        "--rim-cv", help="Choose the rim shrink by cross-validation over the training presses "
                         "(16 extra fits).")] = False,
) -> None:
    """Fit a colour-to-gradient calibration from ball presses, score held-out presses.

    Every circle is checked against its press's colour change (an implausible detected circle
    drops its press), presses taken under another light than the background against one
    another; the report's circles.png shows every press with its circle.

    Example: [bold]vtsbench calibrate rec --out sensor.safetensors --method mlp --holdout 6[/]
    """
    from ..depth.summary import calibrate_to_file

    options = {"bins": bins, "cells": cells, "degree": degree, "pos_degree": pos_degree,
               "width": width, "depth": depth, "epochs": epochs}
    lines = run(calibrate_to_file, recordings, out, method=method, holdout=holdout, seed=seed,
                mm_per_px=mm_per_px, background=background,
                estimate_background=estimate_background, report=report, solver=solver,
                device=device, options=options, circles=circles, markers=markers,
                rim_cv=rim_cv, log=lambda m: typer.echo(m, err=m.startswith("warning")))
    for line in lines:
        typer.echo(line)


def depth(
    images: Annotated[list[str], str_argument(
        help="Images, folders of images, videos or globs such as 'takes/*.mp4' (quoted).")],
    calibration: Annotated[Path, typer.Option(help="Calibration file from `vtsbench calibrate`.")],
    solver: Annotated[Literal["dct", "dst", "masked"], choice(
        help="Poisson solver: dct, dst or masked.")] = "dct",
    out: Annotated[Path, typer.Option(
        "--out", help="Output folder for <name>.npy (float32 mm) and <name>.png; with several "
                      "inputs, a folder's or video's maps go to OUT/<its name>/.")
    ] = Path("depth"),
    device: Annotated[Literal["auto", "cpu", "cuda", "numpy"], choice(
        help="auto (CUDA when present, else numpy), cpu or cuda (torch), numpy.")] = "auto",
    batch: Annotated[int, typer.Option(min=1, max=1024, help="Frames per step.")] = 8,
    range_: Annotated[str | None, str_option(
        "--range", help="Fixed colour scale of the PNGs, MIN,MAX in mm (e.g. -0.2,1.5), the "
                        "same for every frame (default: each frame's own; negative depth is "
                        "drawn in red).")] = None,
) -> None:
    """Reconstruct depth (mm) from tactile images with a calibration.

    Example: [bold]vtsbench depth frames/ 'takes/*.mp4' --calibration sensor.safetensors
    --out depth/ --range -0.2,1.5[/]
    """
    from ..depth.reconstruct import depth_paths, parse_range

    def work() -> int:
        return depth_paths(images, calibration, out, solver=solver,
                           device=None if device == "numpy" else device, batch=batch,
                           value_range=parse_range(range_),
                           log=lambda m: typer.echo(m, err=True))

    n = run(work)
    typer.echo(f"wrote {n} depth map(s) to {out}")
