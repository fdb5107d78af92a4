"""The symmetries of tactile frames with the slip-direction bins mapped to match: the 8
symmetries of the square on square crops, for training augmentation (`dihedral_augment`) and
test-time averaging (`dihedral_average`), shared by the TimeSformer and ResNet recipes (exact
only where a pixel step is the same length along both axes: the isotropic contact crop); and
the two mirrors alone (`flip_augment`), which stay exact on frames resized anisotropically."""

from __future__ import annotations

from collections.abc import Callable

import torch

from vtsbench.labels import MIRROR_X, MIRROR_Y, N_DIRECTIONS


def dihedral(x: torch.Tensor, mirror: bool, turns: int,
             vector: tuple[int, int] | None = None) -> torch.Tensor:
    """One symmetry of the square on a sequence ``x`` (T, C, S, S): a left-right mirror (if
    ``mirror``), then ``turns`` quarter turns counter-clockwise. `vector`: the channels holding
    a motion (x right, y down the rows), whose values turn with the frames: a mirror negates
    x, a quarter turn maps (x, y) to (y, -x)."""
    xi = x.flip(-1) if mirror else x
    # rot90 from the rows axis towards the columns axis turns the picture counter-clockwise
    xi = torch.rot90(xi, turns, dims=(-2, -1))
    if vector is not None:
        cx, cy = vector
        vx, vy = xi[:, cx].clone(), xi[:, cy].clone()
        if mirror:
            vx = -vx
        for _ in range(turns):
            vx, vy = vy, -vx
        xi = xi.clone()
        xi[:, cx], xi[:, cy] = vx, vy
    return xi


def dihedral_label(k: int, mirror: bool, turns: int) -> int:
    """The direction bin k under `dihedral`'s symmetry: a mirror maps k -> (4 - k) mod 8, a
    quarter turn counter-clockwise k -> k + 2."""
    return ((MIRROR_X[k] if mirror else k) + 2 * turns) % N_DIRECTIONS


#: The 8 symmetries of the square as (mirror, quarter turns).
SYMMETRIES: tuple[tuple[bool, int], ...] = tuple((m, t) for m in (False, True) for t in range(4))


def dihedral_augment(x: torch.Tensor, direction: torch.Tensor, generator: torch.Generator,
                     vector: tuple[int, int] | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """Apply a random symmetry of the square (`dihedral`; draws from ``generator``) to each
    square sequence of ``x`` (B, T, C, S, S) and map its direction label to match
    (`dihedral_label`). Exact only on isotropic square crops (the contact crop of the
    TimeSformer recipe); labels < 0 (no direction) stay."""
    if x.shape[-1] != x.shape[-2]:
        raise ValueError(f"quarter turns need square frames, got {tuple(x.shape[-2:])}")
    b = x.shape[0]
    mirror = torch.rand(b, generator=generator) < 0.5
    turns = torch.randint(0, 4, (b,), generator=generator)
    d = direction.long().clone()
    out = []
    for i in range(b):
        out.append(dihedral(x[i], bool(mirror[i]), int(turns[i]), vector))
        if d[i] >= 0:
            d[i] = dihedral_label(int(d[i]), bool(mirror[i]), int(turns[i]))
    return torch.stack(out), d


def dihedral_average(forward: Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor]],
                     x: torch.Tensor, vector: tuple[int, int] | None = None
                     ) -> tuple[torch.Tensor, torch.Tensor]:
    """Test-time average over the 8 symmetries of one square sequence ``x`` (T, C, S, S):
    ``forward`` maps a batch (8, T, C', S, S) to (state logits, direction logits); returns the
    mean state probabilities and the mean direction probabilities, each symmetry's mapped back
    to the unturned sequence's bins (bin k of the original is bin `dihedral_label(k)` of the
    turned one)."""
    batch = torch.stack([dihedral(x, m, t, vector) for m, t in SYMMETRIES])
    state_logits, dir_logits = forward(batch)
    perm = torch.tensor([[dihedral_label(k, m, t) for k in range(N_DIRECTIONS)]
                         for m, t in SYMMETRIES], device=dir_logits.device)
    p_dir = dir_logits.softmax(-1).gather(1, perm).mean(0)
    return state_logits.softmax(-1).mean(0), p_dir


def flip_augment(x: torch.Tensor, direction: torch.Tensor, generator: torch.Generator
                 ) -> tuple[torch.Tensor, torch.Tensor]:
    """Mirror each sequence of ``x`` (B, T, C, H, W) left-right and up-down with p = 0.5 each
    (draws from ``generator``) and map its direction label to match (``MIRROR_X``,
    ``MIRROR_Y``); labels < 0 (no direction) stay. Mirrors commute with the anisotropic resize
    of a 480x640 frame to a square, so the labels stay exact, unlike 90-degree rotations."""
    b = x.shape[0]
    fx = torch.rand(b, generator=generator) < 0.5
    fy = torch.rand(b, generator=generator) < 0.5
    x = torch.where(fx.view(b, 1, 1, 1, 1).to(x.device), x.flip(-1), x)
    x = torch.where(fy.view(b, 1, 1, 1, 1).to(x.device), x.flip(-2), x)
    d = direction.long()
    valid = d >= 0
    mx = torch.tensor(MIRROR_X, device=d.device)[d.clamp(0, len(MIRROR_X) - 1)]
    d = torch.where(valid & fx.to(d.device), mx, d)
    my = torch.tensor(MIRROR_Y, device=d.device)[d.clamp(0, len(MIRROR_Y) - 1)]
    d = torch.where(valid & fy.to(d.device), my, d)
    return x, d
