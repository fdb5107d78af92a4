"""Dual-head TimeSformer for slip: state (static, press, slip) and slip direction (8 bins).

The backbone is transformers' ``TimesformerModel`` with divided space-time attention. Both
heads read the global (CLS) token of the last hidden state. Inputs are float tensors of shape
``(B, T, C, H, W)`` already normalised by the data pipeline; ``C`` is 3 (RGB), 1 (depth) or
4 (RGB-D, depth last).

Two configurations:

- ``paper``: the base model (hidden 768, 12 layers, 12 heads, 224x224, 8 frames, patch 16),
  initialised from ``facebook/timesformer-base-finetuned-ssv2`` found at a local path or in the
  local Hugging Face cache. Nothing is ever downloaded.
- ``small``: hidden 192, 4 layers, 4 heads, 112x112, 8 frames, patch 16; random init; trains
  on a CPU in minutes.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import torch
from torch import nn
from torch.nn import functional as F

from vtsbench.errors import VtsError
from vtsbench.transforms.modality import CHANNELS, channels_of  # noqa: F401 - CHANNELS: old path
from vtsbench.transforms.symmetry import flip_augment  # noqa: F401 - moved there; old path

PAPER_CHECKPOINT = "facebook/timesformer-base-finetuned-ssv2"
NUM_STATES = 3
NUM_DIRECTIONS = 8
SLIP = 2


@dataclass(frozen=True)
class TimesformerSize:
    """Backbone hyper-parameters of one named configuration."""

    image_size: int
    num_frames: int
    patch_size: int
    hidden_size: int
    num_hidden_layers: int
    num_attention_heads: int
    intermediate_size: int
    pretrained: bool


CONFIGS = {
    "paper": TimesformerSize(224, 8, 16, 768, 12, 12, 3072, pretrained=True),
    "small": TimesformerSize(112, 8, 16, 192, 4, 4, 768, pretrained=False),
}


class PretrainedWeightsMissing(VtsError):
    """The pretrained TimeSformer weights are not on disk."""


def backbone_config(
    name: str,
    modality: str = "rgb",
    *,
    image_size: int | None = None,
    num_frames: int | None = None,
    dropout: float = 0.0,
    with_delta: bool = False,
    extra_channels: int = 0,
):
    """The ``TimesformerConfig`` of a named configuration for a modality; ``with_delta`` doubles
    the input channels (each frame followed by its difference to the sequence's first);
    ``extra_channels`` adds more (e.g. 2 of optical flow)."""
    from transformers import TimesformerConfig

    if name not in CONFIGS:
        raise VtsError(f"unknown TimeSformer config {name!r}; expected one of {sorted(CONFIGS)}")
    s = CONFIGS[name]
    return TimesformerConfig(
        image_size=image_size or s.image_size,
        patch_size=s.patch_size,
        num_channels=channels_of(modality) * (2 if with_delta else 1) + extra_channels,
        num_frames=num_frames or s.num_frames,
        hidden_size=s.hidden_size,
        num_hidden_layers=s.num_hidden_layers,
        num_attention_heads=s.num_attention_heads,
        intermediate_size=s.intermediate_size,
        hidden_dropout_prob=dropout,
        attention_probs_dropout_prob=dropout,
        attention_type="divided_space_time",
        vts_extra_channels=extra_channels,
    )


def adapt_patch_weight(weight: torch.Tensor, channels: int, extra: int = 0) -> torch.Tensor:
    """Adapt a 3-channel patch-embedding (or conv) weight ``(O, 3, k, k)`` to ``channels``.

    - 3: unchanged.
    - 1 (depth): the mean of the three RGB filters.
    - 4 (RGB-D): the RGB filters copied unchanged, the depth filter the mean of the three.
    """
    if weight.shape[1] != 3:
        raise ValueError(f"expected a 3-channel weight, got {tuple(weight.shape)}")
    if extra:  # channels after the frames' (optical flow): their filters start at zero
        base = adapt_patch_weight(weight, channels - extra)
        return torch.cat([base, base.new_zeros(base.shape[0], extra, *base.shape[2:])], dim=1)
    mean = weight.mean(dim=1, keepdim=True)
    if channels == 3:
        return weight.clone()
    if channels == 1:
        return mean
    if channels == 4:
        return torch.cat([weight, mean], dim=1)
    if channels in (2, 6, 8):
        # frames and their differences: the frame filters as above, the difference filters 0,
        # so the pretrained model starts out seeing the frames alone
        base = adapt_patch_weight(weight, channels // 2)
        return torch.cat([base, torch.zeros_like(base)], dim=1)
    raise ValueError(f"cannot adapt 3 input channels to {channels}")


def load_pretrained_backbone(config, source: str | Path | None = None, cache_dir=None):
    """A ``TimesformerModel`` of ``config`` initialised from local pretrained weights.

    ``source`` is a folder written by ``save_pretrained`` (a ``config.json`` and the weights);
    ``None`` looks for ``facebook/timesformer-base-finetuned-ssv2`` in the local Hugging Face
    cache (``cache_dir`` or the default). Loading always uses ``local_files_only=True``.
    The checkpoint is 3-channel: for depth (1 channel) the patch-embedding filters are
    averaged over RGB; for RGB-D (4 channels) the RGB filters are copied and the depth filter
    is their mean (see ``adapt_patch_weight``). Position and time embeddings are resized by
    the backbone itself when the image size or frame count differ.
    """
    from transformers import TimesformerModel

    if source is not None and not Path(source).exists():
        raise PretrainedWeightsMissing(
            f"pretrained TimeSformer weights not found at {source}; download "
            f"{PAPER_CHECKPOINT} on a machine with network (e.g. `hf download "
            f"{PAPER_CHECKPOINT} --local-dir DIR`) and pass that folder, or use the 'small' config"
        )
    ident = str(source) if source is not None else PAPER_CHECKPOINT
    try:
        src = TimesformerModel.from_pretrained(ident, local_files_only=True, cache_dir=cache_dir)
    except (OSError, ValueError) as exc:
        raise PretrainedWeightsMissing(
            f"pretrained TimeSformer weights {ident} not available offline ({type(exc).__name__}); "
            f"run `hf download {PAPER_CHECKPOINT}` on a machine with network to fill the "
            "Hugging Face cache, pass a local folder as pretrained_path, or use the 'small' config"
        ) from None
    state = src.state_dict()
    key = "embeddings.patch_embeddings.projection.weight"
    state[key] = adapt_patch_weight(state[key], config.num_channels,
                                    int(getattr(config, "vts_extra_channels", 0)))
    model = TimesformerModel(config)
    own = model.state_dict()
    for k in ("embeddings.position_embeddings", "embeddings.time_embeddings"):
        if k in state and state[k].shape != own[k].shape:
            with_cls = k.endswith("position_embeddings")
            state[k] = _resize_embedding(state[k], own[k].shape, has_cls=with_cls)
    missing, unexpected = model.load_state_dict(state, strict=False)
    if missing or unexpected:
        raise VtsError(
            f"pretrained weights do not match the backbone: missing {missing}, "
            f"unexpected {unexpected}"
        )
    return model


def _resize_embedding(emb: torch.Tensor, shape, has_cls: bool) -> torch.Tensor:
    """Interpolate a learnt position (with CLS) or time embedding to a new length."""
    if not has_cls:  # (1, T, D) over time
        return F.interpolate(emb.transpose(1, 2), size=shape[1], mode="linear").transpose(1, 2)
    cls, grid = emb[:, :1], emb[:, 1:]
    n_old, n_new = round(grid.shape[1] ** 0.5), round((shape[1] - 1) ** 0.5)
    grid = grid.reshape(1, n_old, n_old, -1).permute(0, 3, 1, 2)
    grid = F.interpolate(grid, size=(n_new, n_new), mode="bicubic", align_corners=False)
    return torch.cat([cls, grid.permute(0, 2, 3, 1).reshape(1, n_new * n_new, -1)], dim=1)


class DualHeadTimesformer(nn.Module):
    """TimeSformer backbone with a state head (3 classes) and a direction head (8 classes).

    Both heads are linear layers on the final layer-normalised tokens: the CLS token alone
    (``pool="cls"``, the original TimeSformer classifier) or the CLS token beside the mean of
    the patch tokens (``pool="cls+mean"``). The direction head is trained only on slip samples
    (see ``masked_joint_loss``).
    """

    POOLS = ("cls", "cls+mean")

    def __init__(
        self,
        backbone,
        num_states: int = NUM_STATES,
        num_directions: int = NUM_DIRECTIONS,
        head_dropout: float = 0.0,
        pool: str = "cls",
    ) -> None:
        super().__init__()
        if pool not in self.POOLS:
            raise VtsError(f"pool must be one of {', '.join(self.POOLS)}, not {pool!r}")
        self.backbone = backbone
        self.pool = pool
        hidden = backbone.config.hidden_size * (2 if pool == "cls+mean" else 1)
        self.dropout = nn.Dropout(head_dropout)
        self.state_head = nn.Linear(hidden, num_states)
        self.direction_head = nn.Linear(hidden, num_directions)
        for head in (self.state_head, self.direction_head):
            nn.init.trunc_normal_(head.weight, std=0.02)
            nn.init.zeros_(head.bias)

    @classmethod
    def from_config(
        cls,
        name: str,
        modality: str = "rgb",
        pretrained_path: str | Path | None = None,
        *,
        pretrained: bool | None = None,
        image_size: int | None = None,
        num_frames: int | None = None,
        dropout: float = 0.0,
        cache_dir: str | Path | None = None,
        with_delta: bool = False,
        extra_channels: int = 0,
        pool: str = "cls",
    ) -> DualHeadTimesformer:
        """Build a named configuration (``paper`` or ``small``) for a modality.

        ``pretrained`` defaults to True for ``paper`` (weights from ``pretrained_path`` or the
        local Hugging Face cache; ``PretrainedWeightsMissing`` with a one-line message when
        absent) and to False for ``small`` unless ``pretrained_path`` is given.
        ``image_size`` and ``num_frames`` override the configuration's (tests use 32x32).
        ``with_delta``: twice the modality's channels, frames and their differences;
        ``extra_channels``: more input channels after those (2 for optical flow);
        ``pool``: what the heads read (``cls`` or ``cls+mean``, see the class).
        """
        config = backbone_config(
            name, modality, image_size=image_size, num_frames=num_frames, dropout=dropout,
            with_delta=with_delta, extra_channels=extra_channels,
        )
        if pretrained is None:
            pretrained = CONFIGS[name].pretrained or pretrained_path is not None
        if pretrained:
            backbone = load_pretrained_backbone(config, pretrained_path, cache_dir=cache_dir)
        else:
            from transformers import TimesformerModel

            backbone = TimesformerModel(config)
        return cls(backbone, head_dropout=dropout, pool=pool)

    @property
    def config(self):
        """The backbone's ``TimesformerConfig``."""
        return self.backbone.config

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``x`` ``(B, T, C, H, W)`` -> ``(state_logits (B, 3), direction_logits (B, 8))``."""
        if x.ndim != 5:
            raise ValueError(f"expected (B, T, C, H, W), got shape {tuple(x.shape)}")
        if x.shape[2] != self.config.num_channels:
            raise ValueError(f"expected {self.config.num_channels} channels, got {x.shape[2]}")
        hidden = self.backbone(pixel_values=x).last_hidden_state
        feat = hidden[:, 0]
        if self.pool == "cls+mean":
            feat = torch.cat([feat, hidden[:, 1:].mean(dim=1)], dim=1)
        feat = self.dropout(feat)
        return self.state_head(feat), self.direction_head(feat)


def masked_joint_loss(
    state_logits: torch.Tensor,
    dir_logits: torch.Tensor,
    state: torch.Tensor,
    direction: torch.Tensor,
    lam: float = 1.0,
) -> torch.Tensor:
    """L = L_state + lam * L_dir, with L_dir over slip samples only.

    ``L_state`` is the mean cross-entropy over the batch; ``L_dir`` is the mean cross-entropy
    over the samples whose state is slip (2), i.e. sum_i 1[s_i = slip] CE_i / max(1, n_slip).
    Direction labels of other samples are never read (any integer, even out of range, is
    fine) and the term is exactly zero, with no gradient, when the batch holds no slip.
    """
    state = state.long()
    loss_state = F.cross_entropy(state_logits, state)
    mask = state == SLIP
    if not bool(mask.any()):
        return loss_state + 0.0 * dir_logits.sum()
    loss_dir = F.cross_entropy(dir_logits[mask], direction.long()[mask])
    return loss_state + lam * loss_dir


def count_parameters(module: nn.Module, trainable_only: bool = False) -> int:
    """Number of parameters (elements) of a module."""
    return sum(p.numel() for p in module.parameters() if p.requires_grad or not trainable_only)


def parameter_counts(modality: str = "rgb") -> dict[str, dict[str, int]]:
    """Parameters of each configuration, built on the meta device (no memory, no weights)."""
    out = {}
    for name in CONFIGS:
        with torch.device("meta"):
            model = DualHeadTimesformer.from_config(name, modality, pretrained=False)
        out[name] = {
            "backbone": count_parameters(model.backbone),
            "heads": count_parameters(model.state_head) + count_parameters(model.direction_head),
            "total": count_parameters(model),
        }
    return out
