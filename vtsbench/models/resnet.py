"""ResNet-50 for static recognition: the model and Grad-CAM, which explains its predictions.

The network is torchvision's ``resnet50(weights=None)``; ImageNet weights are optional and
read from a local file only. Inputs are float tensors ``(B, C, H, W)``: RGB in [0, 1]
(normalise after ``vtsbench.transforms.augment.augment``) with C = 3, or depth with C = 1.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from vtsbench.errors import VtsError
from vtsbench.models.timesformer import adapt_patch_weight
from vtsbench.transforms.augment import augment  # noqa: F401 - moved there; old import path
from vtsbench.transforms.modality import channels_of

NUM_CLASSES = 15


def _load_state_dict(path: Path) -> dict[str, torch.Tensor]:
    if path.suffix == ".safetensors":
        from safetensors.torch import load_file

        return load_file(str(path))
    state = torch.load(path, map_location="cpu", weights_only=True)
    if isinstance(state, dict) and "state_dict" in state:
        state = state["state_dict"]
    return state


#: torchvision architectures the static recipe builds: the paper's ResNet-50 and a ResNet-18
#: (11.2 M parameters against 23.5 M) for CPU-sized runs.
ARCHS = ("resnet50", "resnet18")


def static_resnet(
    num_classes: int = NUM_CLASSES,
    modality: str = "rgb",
    pretrained_path: str | Path | None = None,
    arch: str = "resnet50",
) -> nn.Module:
    """A ResNet classifier (``arch``: resnet50, the paper's, or resnet18) for ``rgb``
    (3 channels) or ``depth`` (1 channel) input.

    ``pretrained_path`` is a local file with torchvision's ImageNet state dict of that
    architecture (``.pth`` as torchvision saves it, or ``.safetensors``); nothing is downloaded.
    For depth the first convolution's three RGB filters are averaged into one; the 1000-class
    ImageNet classifier is replaced by a fresh ``num_classes`` one.
    """
    import torchvision.models as tvm

    channels = channels_of(modality)
    if channels not in (1, 3):
        raise VtsError(f"static ResNet supports 'rgb' and 'depth', not {modality!r}")
    if arch not in ARCHS:
        raise VtsError(f"arch must be one of {ARCHS}, not {arch!r}")
    model = getattr(tvm, arch)(weights=None)
    if pretrained_path is not None:
        path = Path(pretrained_path)
        if not path.is_file():
            weights = "ResNet50_Weights.IMAGENET1K_V2" if arch == "resnet50" else \
                "ResNet18_Weights.IMAGENET1K_V1"
            raise VtsError(
                f"ImageNet {arch} weights not found; save torchvision's {weights} state dict "
                "there on a machine with network, or train without pretrained_path",
                path,
            )
        model.load_state_dict(_load_state_dict(path))
    if channels == 1:
        old = model.conv1
        model.conv1 = nn.Conv2d(
            1, old.out_channels, old.kernel_size, old.stride, old.padding, bias=False
        )
        with torch.no_grad():
            model.conv1.weight.copy_(adapt_patch_weight(old.weight, 1))
    model.fc = nn.Linear(model.fc.in_features, num_classes)
    return model


def grad_cam(
    model: nn.Module,
    x: torch.Tensor,
    target: int | Sequence[int] | torch.Tensor | None = None,
    layer: nn.Module | None = None,
) -> torch.Tensor:
    """Grad-CAM heat maps ``(B, H, W)`` in [0, 1] at the input's size.

    ``layer`` defaults to the last convolutional block (``model.layer4``). ``target`` is the
    class explained: ``None`` for each sample's predicted class, an int for all samples, or
    one per sample. The map is ReLU(sum_k alpha_k A_k) with alpha_k the spatial mean of
    d score / d A_k, upsampled bilinearly and scaled by its per-sample maximum (all zeros
    when nothing is positive). Parameter gradients are left untouched.
    """
    layer = model.layer4 if layer is None else layer
    store: dict[str, torch.Tensor] = {}

    def hook(_module, _inputs, output):
        store["act"] = output

    handle = layer.register_forward_hook(hook)
    try:
        with torch.enable_grad():
            x = x.detach().requires_grad_(True)
            logits = model(x)
            if target is None:
                tgt = logits.argmax(dim=1)
            else:
                tgt = torch.as_tensor(target, device=logits.device).long().expand(logits.shape[0])
            score = logits.gather(1, tgt[:, None]).sum()
            act = store["act"]
            (grad,) = torch.autograd.grad(score, act)
    finally:
        handle.remove()
    weights = grad.mean(dim=(2, 3), keepdim=True)
    cam = F.relu((weights * act).sum(dim=1, keepdim=True)).detach()
    cam = F.interpolate(cam, size=x.shape[-2:], mode="bilinear", align_corners=False)[:, 0]
    peak = cam.flatten(1).amax(dim=1).clamp_min(1e-12)[:, None, None]
    cam = (cam / peak).clamp(0.0, 1.0)
    return torch.nan_to_num(cam, nan=0.0)


def _display_image(img: np.ndarray) -> np.ndarray:
    """(C, H, W) -> (H, W, 3) in [0, 1]: RGB clipped, one channel (depth) min-max scaled."""
    if img.shape[0] >= 3:
        return np.clip(np.transpose(img[:3], (1, 2, 0)), 0.0, 1.0)
    d = img[0]
    span = float(d.max() - d.min())
    d = (d - d.min()) / span if span > 0 else np.zeros_like(d)
    return np.repeat(d[..., None], 3, axis=2)


def write_gradcam_overlays(
    images: torch.Tensor,
    cams: torch.Tensor,
    paths: Sequence[str | Path],
    alpha: float = 0.45,
    colormap: str = "jet",
) -> list[Path]:
    """Write one PNG per sample: the image blended with its Grad-CAM map in ``colormap``.

    ``images`` is ``(B, C, H, W)`` (RGB in [0, 1], or one depth channel, scaled per image),
    ``cams`` is ``(B, H, W)`` in [0, 1] (as ``grad_cam`` returns). Returns the paths written.
    """
    import io

    import matplotlib
    from matplotlib.image import imsave

    from ..atomic import write_bytes_atomic
    from ..figures import PRINT_DPI

    if len(paths) != len(images) or len(cams) != len(images):
        raise ValueError("images, cams and paths must have the same length")
    cmap = matplotlib.colormaps[colormap]
    written = []
    for img, cam, path in zip(images, cams, paths, strict=True):
        base = _display_image(img.detach().float().cpu().numpy())
        heat = cmap(np.clip(cam.detach().float().cpu().numpy(), 0.0, 1.0))[..., :3]
        overlay = (1 - alpha) * base + alpha * heat
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        buf = io.BytesIO()  # one pixel per input pixel, stated as PRINT_DPI in the PNG
        imsave(buf, np.clip(overlay, 0.0, 1.0), format="png", dpi=PRINT_DPI)
        write_bytes_atomic(path, buf.getvalue())
        written.append(path)
    return written
