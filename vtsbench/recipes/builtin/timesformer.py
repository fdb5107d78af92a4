"""Dual-head TimeSformer for slip: state (static / press / slip) and direction (8 bins).

The model is `vtsbench.models.timesformer.DualHeadTimesformer` (transformers'
`TimesformerModel`, divided space-time attention) with a state head and a direction head on the
global token, trained with the masked joint loss L = L_state + lambda * 1[state = slip] * L_dir
through `vtsbench.training.train_loop` (seeded batches, safetensors checkpoints, exact resume,
mixed precision on CUDA, DDP under torchrun). Configs: `small` (random init, trains on a CPU in
minutes) and `paper` (base, 224x224, 8 frames, from `facebook/timesformer-base-finetuned-ssv2`
on disk). Inputs: rgb, depth or rgbd, cut around the contact (`crop_px`): by default each
frame's difference to the first and two motion channels, the phase-correlation displacement of
the moving gel from the first frame (`input`, `flow`; `vtsbench.transforms.motion`), trained with
the 8 label-mapped symmetries of the square crop. The checkpoint holds the weights and, in
its metadata, the recipe's config, so `predict` rebuilds the same model.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from vtsbench.errors import VtsError
from vtsbench.labels import N_DIRECTIONS, STATES
from vtsbench.recipes.base import Recipe, WindowPredictor
from vtsbench.recipes.checkpoints import checkpoint_meta
from vtsbench.recipes.data import fit_view, iter_items, per_read, progress_iter
from vtsbench.recipes.monitor import checkpoint_window, train_window_meta
from vtsbench.transforms.contact_crop import FLOW_SOFT_PX, FLOWS

MODALITIES = ("rgb", "depth", "rgbd")


def _frames(x: Any, modality: str, depth_scale_mm: float) -> Any:
    """rgb in [0, 1] -> [-1, 1]; depth (mm) divided by depth_scale_mm. x: (..., C, H, W)."""
    if modality == "rgb":
        return (x - 0.5) / 0.5
    if modality == "depth":
        return x / depth_scale_mm
    out = x.clone()
    out[..., :3, :, :] = (x[..., :3, :, :] - 0.5) / 0.5
    out[..., 3:, :, :] = x[..., 3:, :, :] / depth_scale_mm
    return out


INPUTS = ("frames", "delta", "frames+delta", "frames+flow", "frames+delta+flow", "delta+flow")


def input_mode(config: dict[str, Any]) -> str:
    """`input` of a config; null: `delta+flow` on contact crops (each frame's difference to the
    first and two motion channels), else `frames+delta` (each frame and its difference).
    The `+flow` modes add two channels of motion from the first frame (contact crops only,
    `crop_px`; `flow` says which)."""
    mode = config.get("input") or ("delta+flow" if config.get("crop_px") else "frames+delta")
    if mode not in INPUTS:
        raise VtsError(f"input must be one of {', '.join(INPUTS)}, not {mode!r}")
    if mode.endswith("+flow") and not config.get("crop_px"):
        raise VtsError(f"input {mode!r} needs crop_px (the flow is computed on the crop)")
    return mode


def uses_flow(config: dict[str, Any]) -> bool:
    return input_mode(config).endswith("+flow")


def vector_channels(config: dict[str, Any], channels: int) -> tuple[int, int] | None:
    """The input channels that hold a motion vector (x, y): the last two of a `+flow` input,
    which a turn or mirror of the frames must turn too; None without motion channels."""
    return (channels - 2, channels - 1) if uses_flow(config) else None


def flow_kind(config: dict[str, Any]) -> str | None:
    """The motion channels of a `+flow` input: `shift` (phase-correlation displacement of the
    moving gel) or `dis` (dense optical flow; checkpoints without the key); None without."""
    if not uses_flow(config):
        return None
    kind = config.get("flow") or "dis"
    if kind not in FLOWS:
        raise VtsError(f"flow must be one of {', '.join(FLOWS)}, not {kind!r}")
    mask = config.get("flow_mask")
    if mask not in (None, "contact") or (mask == "contact" and kind != "dis"):
        raise VtsError(f"flow_mask must be null or 'contact' (with flow 'dis'), not {mask!r}")
    return kind


def _normalize(x: Any, config: dict[str, Any]) -> Any:
    """The model's input from a batch (B, T, C, H, W): `frames` as they are (normalised),
    `delta`: each frame minus the sequence's first, times `delta_gain`, clipped to [-1, 1], or
    `frames+delta`: both, concatenated along the channels (2C channels).

    A difference alone does not say which way a texture moved (I(x - d) - I(x) of a periodic
    texture is the same pattern for +d and a shifted -d): on the demo's benchmark the `delta`
    input left the direction head at chance (13.5 % unseen objects, 25.9 % seen), while the
    state head learnt (96.4 %). The frame beside its difference resolves the sign."""
    mode = input_mode(config)
    flow = None
    if mode.endswith("+flow"):  # the last two channels: flow, already scaled (crop_flow)
        x, flow = x[:, :, :-2], x[:, :, -2:]
    x = _frames(x, config["modality"], float(config["depth_scale_mm"]))
    parts = [] if mode.startswith("delta") else [x]
    if "delta" in mode:
        parts.append(((x - x[:, :1]) * float(config.get("delta_gain", 4.0))).clamp(-1.0, 1.0))
    if flow is not None:
        parts.append(flow)
    return parts[0] if len(parts) == 1 else torch_cat(parts, dim=2)


def torch_cat(parts: Any, dim: int) -> Any:
    import torch

    return torch.cat(parts, dim=dim)


class TimesformerRecipe(Recipe):
    name = "timesformer"
    tasks = ("state", "direction")
    nullable = frozenset({"crop_px", "threads"})  # null: the whole frame; torch's default

    def default_config(self) -> dict[str, Any]:
        return {
            "config": "small",          # small | paper
            "modality": "rgb",          # rgb | depth | rgbd
            "image_size": None,         # None: the config's (small 112, paper 224)
            "num_frames": None,         # None: the config's (8)
            "pretrained_path": None,    # folder with the paper's weights (paper: HF cache too)
            "pretrained": None,         # None: paper loads its weights, small does not;
                                        # false: random init (paper-size, no weights on disk)
            "lambda_dir": 1.0,          # weight of the direction term of the masked loss
            "flip": True,               # mirror sequences (labels mapped) while training;
                                        # with crop_px also quarter turns (8 symmetries)
            "slip_oversample": 3,       # draw slipping training sequences this many times
            "fit_parts": ["train"],     # parts of the split trained on (never test)
            "input": None,              # frames | delta (each frame minus the first) |
                                        # frames+delta | frames+flow | frames+delta+flow |
                                        # delta+flow (None: delta+flow with crop_px)
            "pool": "cls+mean",         # what the heads read: cls | cls+mean (checkpoints
                                        # without the key: cls)
            "flow": "shift",            # the +flow channels: shift (phase correlation of
                                        # the moving gel) | dis (dense optical flow)
            "flow_mask": None,          # dis channels: "contact" keeps them only where the
                                        # gel is in contact (the sample's contact masks)
            "flow_soft_px": 0.5,        # shift channels: length (px at the model's input)
                                        # where tanh compression bends (checkpoints without
                                        # the key: 2.0)
            "delta_gain": 4.0,          # delta input: gain before clipping to [-1, 1]
            "tta": True,                # predict: probabilities averaged over the 8 symmetries
                                        # of the square crop, direction bins mapped back
                                        # (contact crops only; checkpoints without the key:
                                        # false)
            "crop_px": 320,             # square of this many sensor px around the contact,
                                        # resized to image_size; None: the whole frame
            "steps": 400,
            "batch_size": 8,
            "lr": 5e-4,
            "weight_decay": 0.05,
            "warmup_steps": 20,
            "schedule": "cosine",
            "grad_clip": 1.0,
            "dropout": 0.0,
            "depth_scale_mm": 1.0,
            "checkpoint_every": 50,
            "amp": True,
            "threads": 1,               # torch CPU threads, pinned: the same figures on any
                                        # machine (null: torch's default); one per process:
                                        # two OpenMP threads on a busy 2-core machine made a
                                        # step 25x slower (17-21 s against 0.6-1.1 s)
        }

    # -- model and data -------------------------------------------------------------------

    @staticmethod
    def _check(config: dict[str, Any]) -> None:
        if config["config"] not in ("small", "paper"):
            raise VtsError(f"config must be 'small' or 'paper', not {config['config']!r}")
        if config["modality"] not in MODALITIES:
            raise VtsError(f"modality must be one of {MODALITIES}, not {config['modality']!r}")
        flow_kind(config)
        if int(config["slip_oversample"]) < 1:
            raise VtsError("slip_oversample must be at least 1")

    @staticmethod
    def _model(config: dict[str, Any], *, pretrained: bool | None) -> Any:
        from vtsbench.models.timesformer import DualHeadTimesformer

        return DualHeadTimesformer.from_config(
            config["config"], config["modality"], config["pretrained_path"],
            pretrained=pretrained, image_size=config["image_size"],
            num_frames=config["num_frames"], dropout=float(config["dropout"]),
            with_delta="frames+delta" in input_mode(config),
            extra_channels=2 if uses_flow(config) else 0,
            pool=config.get("pool") or "cls")

    @staticmethod
    def _view_torch(view: Any, model: Any, config: dict[str, Any]) -> Any:
        size = int(model.config.image_size)
        frames = int(model.config.num_frames)
        if config.get("crop_px"):  # cut around each sequence's contact, kept once cut
            from vtsbench.transforms.crops import SequenceCrops

            return SequenceCrops(view, int(config["crop_px"]), size, frames, config["modality"],
                                 flow=flow_kind(config),
                                 soft_px=float(config.get("flow_soft_px") or FLOW_SOFT_PX),
                                 flow_mask=config.get("flow_mask") == "contact")
        return view.to_torch(config["modality"], size=(size, size), frames=frames,
                             dtype="float32")

    @staticmethod
    def _input_scale(view: Any, data: Any, size: int) -> tuple[float, float]:
        """Model-input pixels per sensor pixel (x, y)."""
        from vtsbench.transforms.crops import SequenceCrops

        if isinstance(data, SequenceCrops) and data.scale is not None:
            return data.scale
        h, w = view.dataset.info.resolution if hasattr(view, "dataset") else (size, size)
        return size / w, size / h

    # -- train / predict --------------------------------------------------------------------

    def train(self, dataset_path: str | Path, split: str, out_dir: str | Path,
              config: dict[str, Any], *, seed: int = 0, device: str = "auto",
              resume: bool = True, progress: bool = True) -> Path:
        import torch
        from torch.utils.data import Subset

        from vtsbench.models.timesformer import masked_joint_loss
        from vtsbench.training import TrainConfig, seed_everything, train_loop
        from vtsbench.transforms.symmetry import dihedral_augment, flip_augment

        self._check(config)
        view = fit_view(dataset_path, split, config.get("fit_parts") or ["train"])
        states = view.index["state_idx"].to_pylist() if "state_idx" in \
            view.index.column_names else []
        keep = [i for i, s in enumerate(states) if s is not None]
        if not keep:
            raise VtsError(f"no slip samples with a known state in {split}/train")
        # slipping sequences drawn `slip_oversample` times as often: only they train the
        # direction head (demo's benchmark, 250 steps, state / direction %: unseen objects
        # x1 95.5 / 16.2, x3 96.4 / 13.5; seen x1 93.4 / 3.7, x3 85.5 / 25.9)
        slip = STATES.index("slip")
        keep += [i for i in keep if states[i] == slip] * (int(config["slip_oversample"]) - 1)
        seed_everything(seed)  # the heads' random init depends on the seed
        model = self._model(config, pretrained=config.get("pretrained"))
        data = Subset(self._view_torch(view, model, config), keep)
        lam = float(config["lambda_dir"])

        def loss_fn(net: torch.nn.Module, batch: Any, dev: torch.device) -> torch.Tensor:
            x, target = batch
            direction = target["direction"]
            if config.get("flip", False):
                # drawn from the global torch RNG, which the checkpoints hold: exact resume
                g = torch.Generator().manual_seed(int(torch.randint(0, 2**62, (1,))))
                # square contact crops allow quarter turns too; resized whole frames mirrors
                # only (see flip_augment)
                if config.get("crop_px"):  # flow channels (the last two) turn with the frames
                    x, direction = dihedral_augment(x, direction, g,
                                                    vector_channels(config, x.shape[2]))
                else:
                    x, direction = flip_augment(x, direction, g)
            x = _normalize(x.to(dev), config)
            state_logits, dir_logits = net(x)
            return masked_joint_loss(state_logits, dir_logits, target["state_idx"].to(dev),
                                     direction.to(dev), lam=lam)

        cfg = TrainConfig.from_recipe(
            config, {"recipe": self.name, "recipe_config": json.dumps(config), "split": split,
                     **train_window_meta(view.dataset.info)})
        # on CUDA the next batch is read while the GPU computes: the crops and flows of 16
        # sequences took 29 % of TimeSformer-base's step on an H100 (benchmarks/gpu.py)
        res = train_loop(model, loss_fn, data, out_dir, cfg, seed=seed, device=device,
                         resume=resume, progress=progress, prefetch=None)
        return res.checkpoint

    def _load(self, checkpoint: str | Path, device: str
              ) -> tuple[Any, dict[str, Any], Any, dict[str, Any]]:
        """The model with its weights on the device, its config, the device and the
        checkpoint's metadata."""
        from vtsbench.environment import deterministic
        from vtsbench.training import load_checkpoint, resolve_device

        meta = checkpoint_meta(checkpoint, self.name, ("recipe_config",))
        config = meta["recipe_config"]
        model = self._model(config, pretrained=False)
        load_checkpoint(checkpoint, model)
        dev = resolve_device(device)
        deterministic(config.get("threads"))
        model.to(dev).eval()
        return model, config, dev, meta

    def predict(self, checkpoint: str | Path, dataset_path: str | Path, split: str,
                part: str = "test", *, device: str = "auto",
                progress: bool = False) -> list[dict[str, Any]]:
        import torch

        import vtsbench
        from vtsbench.transforms.crops import SequenceCrops

        model, config, dev, _ = self._load(checkpoint, device)
        view = vtsbench.load(dataset_path).split(split, part)
        data = self._view_torch(view, model, config)
        rows: list[dict[str, Any]] = []
        self.latency_s = []
        with torch.inference_mode():
            items = iter_items(data, per_read(view, data.arrays))
            for x, target in progress_iter(items, len(data), f"timesformer ({part})", progress):
                t0 = time.perf_counter()
                ps, pd = slip_probs(model, x.to(dev), config)
                # a latency from frames to labels: the crop and motion channels count too
                sid = target["sample_id"]
                prep = data.prep_s[sid] if isinstance(data, SequenceCrops) else 0.0
                self.latency_s.append(time.perf_counter() - t0 + prep)
                rows.append({"sample_id": sid, "task": "state", "pred": STATES[int(ps.argmax())]})
                rows.append({"sample_id": sid, "task": "direction", "pred": int(pd.argmax())})
        self.input_scale_xy = self._input_scale(view, data, int(model.config.image_size))
        return rows

    def window_predictor(self, checkpoint: str | Path, device: str = "auto") -> WindowPredictor:
        """State and direction probabilities of a window of RGB frames, prepared as `predict`
        prepares a slip sample of an RGB dataset (contact crop and motion channels, the
        model's frames evenly spaced; without contact masks, which a live stream does not
        have: the crop centres where the frames change). A checkpoint that reads depth is
        refused: a live RGB stream has none."""
        import torch

        model, config, dev, meta = self._load(checkpoint, device)
        if config["modality"] != "rgb":
            raise VtsError(f"the checkpoint reads {config['modality']}; a live stream gives "
                           "RGB frames alone (train with modality rgb)", checkpoint)
        frames, size = checkpoint_window(meta, checkpoint, int(model.config.num_frames))
        side, keep = int(model.config.image_size), int(model.config.num_frames)
        if keep > frames:
            raise VtsError(f"corrupt checkpoint (the model reads {keep} frames of {frames})",
                           checkpoint)

        def predict(window: Any) -> dict[str, Any]:
            with torch.inference_mode():
                ps, pd = slip_probs(model, sequence_input(window, config, side, keep).to(dev),
                                    config)
            return {"state_probs": ps.numpy(), "direction_probs": pd.numpy()}

        return WindowPredictor(predict, frames, size,
                               {"state": tuple(STATES),
                                "direction": tuple(str(k) for k in range(N_DIRECTIONS))})


def slip_probs(model: Any, x: Any, config: dict[str, Any]) -> tuple[Any, Any]:
    """(state, direction) probabilities on the CPU of one input sequence (T, C, S, S),
    averaged over the 8 symmetries of the square crop when the config asks (`tta`, contact
    crops only): `predict`'s and the monitor's."""
    from vtsbench.transforms.symmetry import dihedral_average

    def forward(batch: Any) -> Any:
        return model(_normalize(batch, config))

    if bool(config.get("tta", False)) and bool(config.get("crop_px")):
        ps, pd = dihedral_average(forward, x, vector_channels(config, x.shape[1]))
    else:
        state_logits, dir_logits = forward(x.unsqueeze(0))
        ps, pd = state_logits[0].softmax(-1), dir_logits[0].softmax(-1)
    return ps.cpu(), pd.cpu()


def sequence_input(rgb: Any, config: dict[str, Any], size: int, frames: int) -> Any:
    """(frames, C, size, size) float32 of a (T, H, W, 3) uint8 RGB sequence, as `predict`
    reads a slip sample of an RGB dataset: its contact crop with the motion channels
    (`SequenceCrops`) or the frames resized (`View.to_torch(dtype="float32")`), `frames` of
    them evenly spaced."""
    import numpy as np
    import torch

    from vtsbench.dataset.read.torch_dataset import frame_numbers, resize

    if config.get("crop_px"):
        from vtsbench.transforms.contact_crop import contact_crop

        x, _ = contact_crop({"rgb": rgb}, int(config["crop_px"]), size, "rgb",
                            flow=flow_kind(config),
                            soft_px=float(config.get("flow_soft_px") or FLOW_SOFT_PX),
                            flow_mask=config.get("flow_mask") == "contact")
        return torch.from_numpy(np.ascontiguousarray(x[frame_numbers(len(x), frames)]))
    t = torch.from_numpy(np.ascontiguousarray(rgb[frame_numbers(len(rgb), frames)]))
    return resize(t.movedim(-1, -3), (size, size)).to(torch.float32).mul_(1.0 / 255.0)


RECIPE = TimesformerRecipe()
