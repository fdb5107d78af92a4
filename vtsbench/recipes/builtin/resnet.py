"""ResNet-50 static object recognition (torchvision; ImageNet weights optional, from disk).

Trains `vtsbench.models.resnet.static_resnet` on the `train` part of a static split with colour
jitter and geometric augmentation (`vtsbench.transforms.augment`, its random draws seeded
from the checkpointed torch RNG, so a resumed run sees the same augmentations), through
`vtsbench.training.train_loop`. Inputs: rgb (ImageNet-normalised after augmentation) or depth
(mm divided by `depth_scale_mm`, its fine relief lifted by `depth_detail_gain`). `predict`
writes one `object` row per sample. With `gradcam: N`, training ends by writing Grad-CAM
overlays of the first N samples of the split's test part to OUT/gradcam/SAMPLE_ID.png.
"""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path
from typing import Any

import torch

from vtsbench.errors import VtsError
from vtsbench.recipes.base import Recipe, WindowPredictor
from vtsbench.recipes.checkpoints import checkpoint_meta
from vtsbench.recipes.data import fit_view, iter_items, per_read, progress_iter, read_items
from vtsbench.recipes.monitor import checkpoint_window, train_window_meta
from vtsbench.transforms.crops import StaticCrops

MODALITIES = ("rgb", "depth")
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)


def _normalize(x: Any, config: dict[str, Any]) -> Any:
    """(B, C, H, W): rgb in [0, 1] -> ImageNet-normalised; depth (mm) / depth_scale_mm, plus
    `depth_detail_gain` times its detail (the depth minus its Gaussian blur of
    `depth_detail_px` at the model's input): a texture's relief of hundredths of a mm rides on a
    dome of tenths, and is what tells fabric from wood."""
    if config["modality"] == "depth":
        y = x / float(config["depth_scale_mm"])
        gain = float(config.get("depth_detail_gain") or 0.0)  # 0 in older checkpoints
        if gain:
            from torchvision.transforms.v2 import functional as TF

            sigma = float(config.get("depth_detail_px") or 2.0)
            k = 2 * math.ceil(3 * sigma) + 1
            y = y + gain * (y - TF.gaussian_blur(y, [k, k], [sigma, sigma]))
        return y
    mean = x.new_tensor(IMAGENET_MEAN).view(1, 3, 1, 1)
    std = x.new_tensor(IMAGENET_STD).view(1, 3, 1, 1)
    return (x - mean) / std


def dihedral_views(x: torch.Tensor) -> torch.Tensor:
    """(1, C, S, S) -> (8, C, S, S): the image under the 8 symmetries of the square
    (`vtsbench.transforms.symmetry.dihedral`: four quarter turns, then the same mirrored).
    Exact on a square crop: no resampling, no fill."""
    from vtsbench.transforms.symmetry import SYMMETRIES, dihedral

    return torch.stack([dihedral(x[0], mirror, turns) for mirror, turns in SYMMETRIES])


class _Normalized(torch.nn.Module):
    """The ResNet on raw (B, C, H, W) input: normalisation first (for Grad-CAM)."""

    def __init__(self, model: torch.nn.Module, config: dict[str, Any]) -> None:
        super().__init__()
        self.net, self.layer4, self.config = model, model.layer4, config

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(_normalize(x, self.config))


class ResnetRecipe(Recipe):
    name = "resnet"
    tasks = ("object",)
    nullable = frozenset({"crop_px", "threads"})  # null: the whole frame; torch's default

    def default_config(self) -> dict[str, Any]:
        return {
            "arch": "resnet50",         # resnet50 (the paper's) | resnet18 (CPU-sized)
            "modality": "rgb",          # rgb | depth
            "image_size": 224,          # square input side
            "pretrained_path": None,    # torchvision ImageNet state dict (.pth/.safetensors)
            "fit_parts": ["train"],     # parts of the split trained on (never test)
            "augment": True,
            "jitter": 0.3,
            "max_rotation": 180.0,      # any rotation: a static imprint's class does not
                                        # depend on how the object was turned
            "crop_px": 320,             # square of sensor px around the contact, resized to
                                        # image_size; None: the whole frame
            "crop_scale": [0.8, 1.0],
            "rotation_fill": "border",  # corners a rotation uncovers: border (each channel's
                                        # median over the crop's outermost pixels: the gel) |
                                        # zero (checkpoints without the key)
            "steps": 300,
            "batch_size": 16,
            "lr": 1e-3,
            "weight_decay": 1e-4,
            "warmup_steps": 20,
            "schedule": "cosine",
            "grad_clip": None,
            "depth_scale_mm": 1.0,
            "depth_detail_gain": 10.0,  # depth input + gain x (depth - its Gaussian blur): lifts
            "depth_detail_px": 2.0,     # fine relief off the dome of the press (83 -> 97 %,
                                        # docs/models.md); blur sigma in px at the model's input;
                                        # 0: plain depth (checkpoints without the key)
            "checkpoint_every": 50,
            "amp": True,
            "gradcam": 0,               # write Grad-CAM overlays of the first N test samples
            "tta": False,               # predict: softmax averaged over the 8 symmetries of the
                                        # square (turns by 90 degrees, mirrors; exact on the
                                        # square crop): within one test frame of off on the
                                        # demo's two seeds for 5x the latency (docs/models.md)
            "threads": 1,               # torch CPU threads, pinned: the same figures on any
                                        # machine (null: torch's default); one per process:
                                        # two OpenMP threads on a busy 2-core machine made a
                                        # step 25x slower (17-21 s against 0.6-1.1 s)
        }

    @staticmethod
    def _model(config: dict[str, Any], num_classes: int, pretrained_path: Any) -> Any:
        from vtsbench.models.resnet import static_resnet

        if config["modality"] not in MODALITIES:
            raise VtsError(f"modality must be one of {MODALITIES}, not {config['modality']!r}")
        return static_resnet(num_classes, config["modality"], pretrained_path,
                             config.get("arch", "resnet50"))

    @staticmethod
    def _data(view: Any, config: dict[str, Any]) -> Any:
        size = int(config["image_size"])
        if config.get("crop_px"):  # cut around each frame's contact, kept once cut
            return StaticCrops(view, int(config["crop_px"]), size, config["modality"])
        return view.to_torch(config["modality"], size=(size, size), dtype="float32")

    def train(self, dataset_path: str | Path, split: str, out_dir: str | Path,
              config: dict[str, Any], *, seed: int = 0, device: str = "auto",
              resume: bool = True, progress: bool = True) -> Path:
        import vtsbench
        from vtsbench.training import TrainConfig, seed_everything, train_loop
        from vtsbench.transforms.augment import augment

        ds = vtsbench.load(dataset_path)
        parts = config.get("fit_parts") or ["train"]
        view = fit_view(dataset_path, split, parts)
        if len(view) == 0:
            raise VtsError(f"no samples in {split}/{'+'.join(parts)}")
        seed_everything(seed)  # the classifier's random init depends on the seed
        objects = list(ds.info.objects)
        model = self._model(config, len(objects), config["pretrained_path"])
        data = self._data(view, config)
        modality = config["modality"]
        aug = dict(jitter=float(config["jitter"]), max_rotation=float(config["max_rotation"]),
                   crop_scale=tuple(config["crop_scale"]),
                   fill=config.get("rotation_fill") or "zero")

        def loss_fn(net: torch.nn.Module, batch: Any, dev: torch.device) -> torch.Tensor:
            x, target = batch
            if config["augment"]:
                # drawn from the global torch RNG, which the checkpoints hold: exact resume
                g = torch.Generator().manual_seed(int(torch.randint(0, 2**62, (1,))))
                x = augment(x, modality, g, **aug)
            logits = net(_normalize(x.to(dev), config))
            return torch.nn.functional.cross_entropy(logits, target["class_idx"].long().to(dev))

        cfg = TrainConfig.from_recipe(
            config, {"recipe": self.name, "recipe_config": json.dumps(config), "split": split,
                     "objects": json.dumps(objects), **train_window_meta(ds.info, 1)})
        res = train_loop(model, loss_fn, data, out_dir, cfg, seed=seed, device=device,
                         resume=resume, progress=progress)
        n_cam = int(config["gradcam"] or 0)
        if n_cam > 0 and int(os.environ.get("RANK", 0)) == 0:
            self.write_gradcam(res.checkpoint, dataset_path, split, Path(out_dir) / "gradcam",
                               n_cam, device=device)
        return res.checkpoint

    def _load(self, checkpoint: str | Path, device: str) -> tuple[Any, dict[str, Any], Any]:
        model, config, dev, _ = self._load_meta(checkpoint, device)
        return model, config, dev

    def _load_meta(self, checkpoint: str | Path, device: str
                   ) -> tuple[Any, dict[str, Any], Any, dict[str, Any]]:
        from vtsbench.training import load_checkpoint, resolve_device

        meta = checkpoint_meta(checkpoint, self.name, ("recipe_config", "objects"))
        config, objects = meta["recipe_config"], meta["objects"]
        model = self._model(config, len(objects), None)
        load_checkpoint(checkpoint, model)
        dev = resolve_device(device)
        from vtsbench.environment import deterministic

        deterministic(config.get("threads"))
        model.to(dev).eval()
        return model, config, dev, meta

    def write_gradcam(self, checkpoint: str | Path, dataset_path: str | Path, split: str,
                      out: str | Path, n: int, part: str = "test", *,
                      device: str = "auto") -> list[Path]:
        """Grad-CAM overlays (PNG) of the first n samples of split/part, as out/ID.png."""
        import vtsbench
        from vtsbench.models.resnet import grad_cam, write_gradcam_overlays

        model, config, dev = self._load(checkpoint, device)
        view = vtsbench.load(dataset_path).split(split, part)
        data = self._data(view, config)
        items = read_items(data, range(min(n, len(data))))
        if not items:
            return []
        x = torch.stack([it[0] for it in items]).to(dev)
        wrapped = _Normalized(model, config)
        cams = grad_cam(wrapped, x)
        paths = [Path(out) / f"{it[1]['sample_id']}.png" for it in items]
        return write_gradcam_overlays(x.detach().cpu(), cams.detach().cpu(), paths)

    def predict(self, checkpoint: str | Path, dataset_path: str | Path, split: str,
                part: str = "test", *, device: str = "auto",
                progress: bool = False) -> list[dict[str, Any]]:
        import vtsbench

        model, config, dev = self._load(checkpoint, device)
        view = vtsbench.load(dataset_path).split(split, part)
        data = self._data(view, config)
        tta = bool(config.get("tta", False))  # False in checkpoints written before the option
        rows: list[dict[str, Any]] = []
        self.latency_s = []
        with torch.inference_mode():
            items = iter_items(data, per_read(view, data.arrays))
            for x, target in progress_iter(items, len(data), f"resnet ({part})", progress):
                t0 = time.perf_counter()
                probs = class_probs(model, x.unsqueeze(0).to(dev), config, tta)
                pred = int(probs.argmax())
                self.latency_s.append(time.perf_counter() - t0)
                rows.append({"sample_id": target["sample_id"], "task": "object", "pred": pred})
        return rows

    def window_predictor(self, checkpoint: str | Path, device: str = "auto") -> WindowPredictor:
        """The object probabilities of the newest frame of a window (one frame), prepared as
        `predict` prepares a static sample (the contact crop, without contact masks: a live
        stream has none, so the crop centres where the frame changes, as on an RGB-only
        dataset). A depth checkpoint is refused: a live RGB stream has no depth."""
        model, config, dev, meta = self._load_meta(checkpoint, device)
        if config["modality"] != "rgb":
            raise VtsError(f"the checkpoint reads {config['modality']}; a live stream gives "
                           "RGB frames alone (train with modality rgb)", checkpoint)
        frames, size = checkpoint_window(meta, checkpoint, 1)
        tta = bool(config.get("tta", False))

        def predict(window: Any) -> dict[str, Any]:
            with torch.inference_mode():
                x = frame_input(window[-1], config).unsqueeze(0).to(dev)
                return {"object_probs": class_probs(model, x, config, tta).cpu().numpy()}

        return WindowPredictor(predict, frames, size, {"object": tuple(meta["objects"])})


def class_probs(model: Any, x: torch.Tensor, config: dict[str, Any], tta: bool
                ) -> torch.Tensor:
    """The class probabilities of one input (1, C, S, S), averaged over the 8 symmetries of
    the square with `tta`: `predict`'s and the monitor's."""
    if tta:
        x = dihedral_views(x)
    return model(_normalize(x, config)).softmax(-1).mean(0)


def frame_input(rgb: Any, config: dict[str, Any]) -> torch.Tensor:
    """(3, S, S) float32 in [0, 1] of one (H, W, 3) uint8 RGB frame, as `predict` reads a static
    sample of an RGB dataset: its contact crop (`crop_px`, `StaticCrops`) or the whole frame
    resized (`View.to_torch(dtype="float32")`)."""
    import numpy as np

    size = int(config["image_size"])
    if config.get("crop_px"):
        from vtsbench.transforms.contact_crop import contact_crop

        x, _ = contact_crop({"rgb": rgb[None], "contact": None}, int(config["crop_px"]), size,
                            "rgb")
        return torch.from_numpy(np.ascontiguousarray(x[0]))
    from vtsbench.dataset.read.torch_dataset import resize

    t = resize(torch.from_numpy(np.ascontiguousarray(rgb)).movedim(-1, -3), (size, size))
    return t.to(torch.float32).mul_(1.0 / 255.0)


RECIPE = ResnetRecipe()
