"""Training-time augmentation of static tactile images (B, C, H, W): colour jitter on the RGB
channels and the same flips, rotation and random resized crop on every channel, each draw from
a given torch.Generator (the ResNet recipe seeds it from the checkpointed RNG, so a resumed run
sees the same augmentations)."""

from __future__ import annotations

import math

import torch

from vtsbench.transforms.modality import channels_of


def _uniform(generator: torch.Generator, lo: float, hi: float) -> float:
    return lo + (hi - lo) * float(torch.rand((), generator=generator))


def _border_median(img: torch.Tensor) -> list[float]:
    """Per channel, the median of the outermost row and column pixels of (C, H, W)."""
    edge = torch.cat([img[:, 0], img[:, -1], img[:, 1:-1, 0], img[:, 1:-1, -1]], dim=1)
    return [float(v) for v in edge.median(dim=1).values]


def augment(
    batch: torch.Tensor,
    modality: str,
    generator: torch.Generator,
    *,
    jitter: float = 0.3,
    max_rotation: float = 15.0,
    crop_scale: tuple[float, float] = (0.8, 1.0),
    fill: str = "zero",
) -> torch.Tensor:
    """Training-time augmentation of a batch ``(B, C, H, W)``, deterministic given ``generator``.

    Per sample: colour jitter (brightness, contrast, saturation by factors in
    [1 - jitter, 1 + jitter]) on the RGB channels only (``rgb``, and the first three of
    ``rgbd``); then the same geometric transform on every channel: horizontal and vertical
    flips (p = 0.5 each), a rotation in [-max_rotation, max_rotation] degrees (``fill``) and a
    random resized crop back to (H, W). Depth values are only moved, never rescaled (bilinear
    resampling aside). RGB is expected in [0, 1]. ``fill``: what the rotation brings into the
    corners: ``zero``, or ``border``, each channel's median over the sample's outermost pixels
    (on a contact crop the untouched gel, so a turned crop has no black corners that no test
    frame has).
    """
    if fill not in ("zero", "border"):
        raise ValueError(f"fill must be 'zero' or 'border', not {fill!r}")
    from torchvision.transforms.v2 import functional as TF

    channels = channels_of(modality)
    if batch.ndim != 4 or batch.shape[1] != channels:
        raise ValueError(f"expected (B, {channels}, H, W) for {modality}, got {tuple(batch.shape)}")
    h, w = batch.shape[-2:]
    out = []
    for img in batch:
        if modality in ("rgb", "rgbd"):
            rgb = img[:3]
            rgb = TF.adjust_brightness(rgb, _uniform(generator, 1 - jitter, 1 + jitter))
            rgb = TF.adjust_contrast(rgb, _uniform(generator, 1 - jitter, 1 + jitter))
            rgb = TF.adjust_saturation(rgb, _uniform(generator, 1 - jitter, 1 + jitter))
            img = torch.cat([rgb, img[3:]], dim=0)
        if float(torch.rand((), generator=generator)) < 0.5:
            img = TF.horizontal_flip(img)
        if float(torch.rand((), generator=generator)) < 0.5:
            img = TF.vertical_flip(img)
        angle = _uniform(generator, -max_rotation, max_rotation)
        img = TF.rotate(img, angle, interpolation=TF.InterpolationMode.BILINEAR,
                        fill=_border_median(img) if fill == "border" else 0.0)
        area = _uniform(generator, *crop_scale) * h * w
        ratio = math.exp(_uniform(generator, math.log(3 / 4), math.log(4 / 3)))
        ch = min(h, max(1, round(math.sqrt(area / ratio))))
        cw = min(w, max(1, round(math.sqrt(area * ratio))))
        top = int(torch.randint(0, h - ch + 1, (), generator=generator))
        left = int(torch.randint(0, w - cw + 1, (), generator=generator))
        img = TF.resized_crop(
            img,
            top,
            left,
            ch,
            cw,
            [h, w],
            interpolation=TF.InterpolationMode.BILINEAR,
            antialias=True,
        )
        out.append(img)
    return torch.stack(out)
