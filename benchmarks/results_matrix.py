"""The results page's run matrix as data: each profile's recipe configurations and the splits
they are trained on (`Run`), the paper's figures the page compares with, and what the page says
of each profile's compute."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

#: The paper's figures (accuracy %), its own recordings and splits: a reference, not an entry.
PAPER = {
    ("slip", "seen"): {"state": 99.68, "direction": 96.95},
    ("slip", "unseen_objects"): {"state": 95.5, "direction": 91.5},
    ("static", "rgb"): {"object": 98.80},
    ("static", "depth"): {"object": 96.06},
}
#: The slip splits every profile trains on, in the page's order.
SLIP_SPLITS = ("unseen_objects", "seen")
MODALITIES = ("rgb", "depth")


@dataclass
class Run:
    """One recipe configuration trained on one split and scored on its test part."""

    method: str           # leaderboard name: recipe-size-modality
    recipe: str
    split: str
    config: dict[str, Any] = field(default_factory=dict)
    dataset: str = "synthetic"   # which dataset (key of the --dataset/--octopi paths)


#: The demo profile's configs (CPU, 2 cores, the whole `make demo` under 15 minutes), sized for
#: the benchmark's sensor (240x320 at 0.06 mm/px): a 128 px crop is 7.7 mm of gel around the
#: contact. The motion channels are the crop's dense DIS flow (`flow: dis`) kept where the gel
#: is in contact (`flow_mask: contact`): on generator-2 slips the whole-crop `shift` locks onto
#: the gel's fixed pattern like any registration, and the still gel dilutes a dense flow.
DEMO_TSF = {"config": "small", "modality": "rgb", "image_size": 64, "crop_px": 128,
            "input": "delta+flow", "flow": "dis", "flow_mask": "contact", "pool": "cls+mean",
            "steps": 300, "batch_size": 8,
            "checkpoint_every": 100, "fit_parts": ["train", "val"]}
DEMO_RESNET = {"arch": "resnet18", "image_size": 128, "crop_px": 160, "steps": 300,
               "batch_size": 16, "checkpoint_every": 100, "gradcam": 4,
               "fit_parts": ["train", "val"]}
#: Steps per modality in the demo: depth (one channel, no colour) needs twice RGB's to pass 85 %
#: (docs/models.md, "Which knob buys how much").
DEMO_RESNET_STEPS = {"rgb": 300, "depth": 600}
#: The v2 profile: the published benchmark (`vtsbench benchmark v2`: 3,600 sequences, 3,000
#: static frames) with the demo's model sizes trained longer, on 2 CPU cores.
V2_STEPS = {"timesformer": 1500, "resnet": {"rgb": 600, "depth": 1200}}
#: The results profile (paper scale: ~8,000 sequences, ~19,000 static frames, paper-size
#: models): steps on a GPU, and the fewer steps it falls back to on a CPU (the page says so).
PAPER_TSF = {"config": "paper", "modality": "rgb", "crop_px": 256,
             "input": "delta+flow", "flow": "shift", "flow_soft_px": 0.5, "pool": "cls+mean",
             "batch_size": 16,
             "lr": 1e-4, "warmup_steps": 200, "checkpoint_every": 500, "threads": None}
PAPER_RESNET = {"arch": "resnet50", "image_size": 224, "crop_px": 320, "batch_size": 32,
                "checkpoint_every": 500, "gradcam": 8, "threads": None}
PAPER_STEPS = {"gpu": {"timesformer": 6000, "resnet": 6000},
               "cpu": {"timesformer": 300, "resnet": 600}}
#: TimeSformer-base batch: 16 on a GPU; on a CPU 4, since one training run at 16 (8 frames at
#: 224) passed 23.7 GB and was killed for memory on a 24 GiB machine.
PAPER_TSF_BATCH = {"gpu": 16, "cpu": 4}
#: The flow baseline in every profile: frames resized to a quarter.
FLOW = {"scale": 0.25}
#: ResNet-18 RGB on the real GelSight Mini videos (--octopi), whole frames at 112 px.
OCTOPI_RESNET = {**DEMO_RESNET, "modality": "rgb", "crop_px": None, "image_size": 112,
                 "steps": 800, "gradcam": 8}


def _demo() -> list[Run]:
    runs = []
    for split in SLIP_SPLITS:
        runs.append(Run("flow-contact", "flow", split, dict(FLOW)))
        runs.append(Run("timesformer-small-rgb", "timesformer", split, dict(DEMO_TSF)))
    for mod in MODALITIES:
        runs.append(Run(f"resnet18-{mod}", "resnet", "static_sessions",
                        {**DEMO_RESNET, "modality": mod, "steps": DEMO_RESNET_STEPS[mod]}))
    return runs


def _v2() -> list[Run]:
    tsf = {**DEMO_TSF, "steps": V2_STEPS["timesformer"], "checkpoint_every": 250}
    runs = []
    for split in SLIP_SPLITS:
        runs.append(Run("flow-contact", "flow", split, dict(FLOW)))
        runs.append(Run("timesformer-small-rgb", "timesformer", split, dict(tsf)))
    runs.append(Run("timesformer-small-depth", "timesformer", "unseen_objects",
                    {**tsf, "modality": "depth"}))
    for mod in MODALITIES:
        runs.append(Run(f"resnet18-{mod}", "resnet", "static_sessions",
                        {**DEMO_RESNET, "modality": mod,
                         "steps": V2_STEPS["resnet"][mod], "checkpoint_every": 200}))
    return runs


def _results(gpu: bool, pretrained: str | None) -> list[Run]:
    where = "gpu" if gpu else "cpu"
    steps = PAPER_STEPS[where]
    tsf = {**PAPER_TSF, "steps": steps["timesformer"], "pretrained_path": pretrained,
           "batch_size": PAPER_TSF_BATCH[where],
           # the 8-view test-time average costs 25 s a sequence on a 2-core CPU (3 without)
           "tta": gpu,
           "pretrained": pretrained is not None}
    runs = []
    for split in SLIP_SPLITS:
        runs.append(Run("flow-contact", "flow", split, dict(FLOW)))
        runs.append(Run("timesformer-base-rgb", "timesformer", split, dict(tsf)))
    runs.append(Run("timesformer-base-depth", "timesformer", "seen",
                    {**tsf, "modality": "depth"}))
    for mod in MODALITIES:
        runs.append(Run(f"resnet50-{mod}", "resnet", "static_sessions",
                        {**PAPER_RESNET, "modality": mod, "steps": steps["resnet"]}))
    return runs


def profile_runs(profile: str, octopi: bool, *, gpu: bool = False,
                 pretrained: str | None = None) -> list[Run]:
    """The runs of a profile: `demo` (CPU-sized models on the demo's dataset, about 8 minutes
    on 2 CPU cores), `v2` (the demo's models trained longer on the published benchmark) or
    `results` (the paper's models, TimeSformer-base at 224 and ResNet-50, meant for a
    paper-scale dataset on a GPU; on a CPU with PAPER_STEPS["cpu"] steps); with octopi, ResNet-18
    RGB on the real videos too. `pretrained`: folder of the SSv2 TimeSformer weights (results
    profile; without it the paper-size TimeSformer starts from random weights, and the page
    says so)."""
    if profile == "v2":
        runs = _v2()
    elif profile == "demo":
        runs = _demo()
    else:
        runs = _results(gpu, pretrained)
    if octopi:
        runs.append(Run("resnet18-rgb", "resnet", "static_sessions", dict(OCTOPI_RESNET),
                        dataset="octopi"))
    return runs


def select(runs: list[Run], splits: str | None, steps: int | None) -> list[Run]:
    """The runs of the given comma-separated splits (all without), every trained run with
    `steps` steps when given (a smoke run of the whole path)."""
    if splits:
        keep = set(splits.split(","))
        runs = [r for r in runs if r.split in keep]
    if steps is not None:
        runs = [Run(r.method, r.recipe, r.split, {**r.config, "steps": steps}
                    if "steps" in r.config else r.config, r.dataset) for r in runs]
    return runs


def expected_cost(run: Run) -> float:
    """Rough training seconds of a run, to start the long ones first: steps times the seconds
    of one demo-size step (measured side by side on 2 cores: ResNet-18 at 128 px, batch 16,
    0.7 s; small TimeSformer at 64 px, batch 8, 0.5 s); the flow recipe fits a tree in seconds."""
    per_step = {"resnet": 0.7, "timesformer": 0.5}.get(run.recipe, 0.0)
    return per_step * run.config.get("steps", 0)


def steps_note(profile: str, gpu: bool, pretrained: str | None) -> str:
    """What the page must say about the compute its figures had."""
    if profile == "v2":
        return ("v2 profile: the published benchmark (`vtsbench benchmark v2`), models of the "
                "demo's size trained longer on 2 CPU cores "
                f"({V2_STEPS['timesformer']} TimeSformer steps, ResNet "
                f"{V2_STEPS['resnet']['rgb']} on RGB and {V2_STEPS['resnet']['depth']} on depth); "
                "the paper-scale results profile (`make results`) was not run for this page.")
    if profile == "demo":
        return ("Demo profile: CPU-sized models and steps (what `make demo` trains on 2 CPU "
                "cores); the paper-scale results profile (`make results`) was not run for this "
                "page.")
    cpu, gpu_ = PAPER_STEPS["cpu"], PAPER_STEPS["gpu"]
    where = "on a GPU" if gpu else (
        f"on the CPU, with fewer steps than on a GPU ({cpu['timesformer']} TimeSformer and "
        f"{cpu['resnet']} ResNet steps against {gpu_['timesformer']} and {gpu_['resnet']}) "
        f"and a TimeSformer batch of {PAPER_TSF_BATCH['cpu']} against "
        f"{PAPER_TSF_BATCH['gpu']} (memory), no test-time averaging (8x the latency): the "
        "paper-size models are under-trained here")
    init = "from the SSv2 weights" if pretrained else "from random weights (no SSv2 weights given)"
    return f"Results profile: paper-size models trained {where}; TimeSformer-base {init}."
