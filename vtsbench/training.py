"""A generic, seeded torch training loop for recipes: safetensors checkpoints, exact resume,
progress bar, CUDA with mixed precision when present, DDP under `torchrun`.

Determinism: the samples of step s are drawn from a permutation of the dataset seeded by
(seed, epoch), so a resumed run reads the same batches as an uninterrupted one without any
data-loader state. A step's samples are read together, through the dataset's `__getitems__`
where it has one (a view's `to_torch()`, the crop datasets: one batched read of the arrays),
which gives the same items as reading them one by one. A checkpoint holds the model, the
optimizer state, the step, the AMP scaler and the RNG states (torch CPU and CUDA, numpy,
Python), so resuming on CPU from step k gives bit-identical weights to never stopping.
Checkpoints are safetensors: tensors plus JSON in the string metadata; nothing is pickled.

Under `torchrun --nproc_per_node N` (RANK / WORLD_SIZE set) the loop joins a process group (NCCL
on CUDA, gloo on CPU), wraps the model in DistributedDataParallel and gives each rank its
slice of every global batch; rank 0 writes the checkpoints and draws the progress bar.
"""

from __future__ import annotations

import json
import math
import os
import random
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from .environment import deterministic
from .recipes.data import read_items

CHECKPOINT_DIR = "checkpoints"
FINAL = "checkpoint.safetensors"


@dataclass
class TrainConfig:
    """Options of `train_loop` (a recipe maps its config onto these)."""

    steps: int = 100
    batch_size: int = 8
    lr: float = 1e-3
    weight_decay: float = 0.0
    warmup_steps: int = 0
    schedule: str = "constant"  # or "cosine"
    grad_clip: float | None = None
    checkpoint_every: int = 50
    keep_checkpoints: int = 2
    amp: bool = True  # mixed precision, on CUDA only
    extra: dict[str, Any] = field(default_factory=dict)  # written into the checkpoint metadata
    threads: int | None = None  # torch CPU threads (pinned: reductions depend on it)

    @classmethod
    def from_recipe(cls, config: dict[str, Any], extra: dict[str, Any]) -> TrainConfig:
        """The loop options held in a torch recipe's config under the same names."""
        return cls(steps=int(config["steps"]), batch_size=int(config["batch_size"]),
                   lr=float(config["lr"]), weight_decay=float(config["weight_decay"]),
                   warmup_steps=int(config["warmup_steps"]), schedule=config["schedule"],
                   grad_clip=config["grad_clip"],
                   checkpoint_every=int(config["checkpoint_every"]), amp=bool(config["amp"]),
                   extra=extra, threads=config.get("threads"))


@dataclass
class TrainResult:
    model: torch.nn.Module
    step: int
    checkpoint: Path
    resumed_from: int
    losses: list[float]


# -- device, seeds, distributed ------------------------------------------------------------


def resolve_device(device: str | torch.device | None = "auto") -> torch.device:
    """`auto`: the local rank's CUDA device when CUDA is present, else the CPU."""
    if device is None or str(device) == "auto":
        if torch.cuda.is_available():
            return torch.device("cuda", int(os.environ.get("LOCAL_RANK", 0)))
        return torch.device("cpu")
    return torch.device(device)


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)


def dist_env() -> tuple[int, int]:
    """(rank, world size) from torchrun's environment; (0, 1) when not launched by it."""
    return int(os.environ.get("RANK", 0)), int(os.environ.get("WORLD_SIZE", 1))


def init_distributed(device: torch.device) -> bool:
    """Join the process group when launched with WORLD_SIZE > 1; True when distributed."""
    import torch.distributed as dist

    rank, world = dist_env()
    if world <= 1:
        return False
    if not dist.is_initialized():
        backend = "nccl" if device.type == "cuda" else "gloo"
        if device.type == "cuda":
            torch.cuda.set_device(device)
        dist.init_process_group(backend=backend, rank=rank, world_size=world)
        # Leave the group at exit: a gloo group still open when the interpreter ends can abort
        # the process ("terminate called without an active exception") after the work is done.
        import atexit

        atexit.register(_leave_group)
    return True


def _leave_group() -> None:
    import torch.distributed as dist

    if dist.is_initialized():
        dist.destroy_process_group()


def batch_indices(n: int, step: int, batch_size: int, seed: int, rank: int = 0,
                  world: int = 1) -> list[int]:
    """Dataset indices of this rank's share of global step `step` (0-based).

    Epoch e is a permutation seeded by (seed, e); a global batch is batch_size consecutive
    entries of the epochs laid end to end, split between ranks by striding.
    """
    out = []
    start = step * batch_size
    cache: dict[int, list[int]] = {}
    for pos in range(start, start + batch_size):
        epoch, i = divmod(pos, n)
        if epoch not in cache:
            g = torch.Generator().manual_seed(seed * 1_000_003 + epoch)
            cache[epoch] = torch.randperm(n, generator=g).tolist()
        out.append(cache[epoch][i])
    return out[rank::world]


def lr_factor(step: int, cfg: TrainConfig) -> float:
    if cfg.warmup_steps and step < cfg.warmup_steps:
        return (step + 1) / cfg.warmup_steps
    if cfg.schedule == "cosine":
        span = max(1, cfg.steps - cfg.warmup_steps)
        return 0.5 * (1 + math.cos(math.pi * min(1.0, (step - cfg.warmup_steps) / span)))
    return 1.0


# -- checkpoints -----------------------------------------------------------------------------


def _unwrap(model: torch.nn.Module) -> torch.nn.Module:
    return model.module if hasattr(model, "module") else model


def _rng_state() -> dict[str, Any]:
    np_state = np.random.get_state()
    return {"python": [random.getstate()[0], list(random.getstate()[1]),
                       random.getstate()[2]],
            "numpy": [np_state[0], np_state[1].tolist(), *np_state[2:]]}


def _set_rng_state(state: dict[str, Any]) -> None:
    v, internal, gauss = state["python"]
    random.setstate((v, tuple(internal), gauss))
    n = state["numpy"]
    np.random.set_state((n[0], np.array(n[1], dtype=np.uint32), *n[2:]))


def save_checkpoint(path: str | Path, model: torch.nn.Module,
                    optimizer: torch.optim.Optimizer | None = None, step: int = 0,
                    scaler: Any = None, metadata: dict[str, Any] | None = None) -> Path:
    """Write model (`model.*`), optimizer state (`optim.*`), RNG states and step to safetensors,
    through a temporary file and a rename."""
    from safetensors.torch import save_file

    from .atomic import replacing

    path = Path(path)
    tensors: dict[str, torch.Tensor] = {}
    for k, v in _unwrap(model).state_dict().items():
        tensors[f"model.{k}"] = v.detach().cpu().contiguous()
    meta: dict[str, str] = {"step": str(step), "format": "vtsbench-train-1"}
    if optimizer is not None:
        sd = optimizer.state_dict()
        scalars: dict[str, dict[str, Any]] = {}
        for pid, st in sd["state"].items():
            for key, val in st.items():
                if torch.is_tensor(val):
                    tensors[f"optim.{pid}.{key}"] = val.detach().cpu().contiguous()
                else:
                    scalars.setdefault(str(pid), {})[key] = val
        meta["optim_param_groups"] = json.dumps(sd["param_groups"])
        meta["optim_scalars"] = json.dumps(scalars)
    tensors["rng.torch"] = torch.get_rng_state()
    if torch.cuda.is_available():
        for i, s in enumerate(torch.cuda.get_rng_state_all()):
            tensors[f"rng.cuda.{i}"] = s
    meta["rng"] = json.dumps(_rng_state())
    if scaler is not None:
        meta["scaler"] = json.dumps(scaler.state_dict())
    for k, v in (metadata or {}).items():
        meta[k] = v if isinstance(v, str) else json.dumps(v)
    path.parent.mkdir(parents=True, exist_ok=True)
    with replacing(path) as tmp:
        save_file(tensors, str(tmp), metadata=meta)
    return path


def load_checkpoint(path: str | Path, model: torch.nn.Module | None = None,
                    optimizer: torch.optim.Optimizer | None = None, scaler: Any = None,
                    restore_rng: bool = False) -> dict[str, str]:
    """Load what save_checkpoint wrote into model / optimizer / scaler; returns the metadata.
    A checkpoint that is damaged or does not fit the model is a one-line VtsError."""
    from .errors import VtsError
    from .recipes.checkpoints import check_checkpoint

    check_checkpoint(path)
    try:
        return _load_checkpoint(path, model, optimizer, scaler, restore_rng)
    except (KeyError, ValueError, TypeError, IndexError, RuntimeError) as e:
        text = str(e).strip().splitlines()[0][:120] if str(e).strip() else type(e).__name__
        raise VtsError(f"checkpoint does not fit ({text})", path) from None


def _load_checkpoint(path: str | Path, model: torch.nn.Module | None,
                     optimizer: torch.optim.Optimizer | None, scaler: Any,
                     restore_rng: bool) -> dict[str, str]:
    from safetensors import safe_open

    with safe_open(str(path), framework="pt") as fh:
        meta = fh.metadata() or {}
        tensors = {k: fh.get_tensor(k) for k in fh.keys()}  # noqa: SIM118 - not a dict
    if model is not None:
        target = _unwrap(model)
        state = {k[6:]: v for k, v in tensors.items() if k.startswith("model.")}
        target.load_state_dict(state)
    if optimizer is not None and "optim_param_groups" in meta:
        groups = json.loads(meta["optim_param_groups"])
        for g, cur in zip(groups, optimizer.state_dict()["param_groups"], strict=True):
            for k, v in cur.items():  # JSON made tuples lists: give them back their type
                if isinstance(v, tuple) and isinstance(g.get(k), list):
                    g[k] = tuple(g[k])
        st: dict[int, dict[str, Any]] = {}
        for k, v in tensors.items():
            if k.startswith("optim."):
                _, pid, key = k.split(".", 2)
                st.setdefault(int(pid), {})[key] = v
        for pid, vals in json.loads(meta.get("optim_scalars", "{}")).items():
            st.setdefault(int(pid), {}).update(vals)
        optimizer.load_state_dict({"state": st, "param_groups": groups})
    if scaler is not None and "scaler" in meta:
        scaler.load_state_dict(json.loads(meta["scaler"]))
    if restore_rng:
        torch.set_rng_state(tensors["rng.torch"])
        cuda = [tensors[k] for k in sorted(tensors) if k.startswith("rng.cuda.")]
        if cuda and torch.cuda.is_available() and len(cuda) == torch.cuda.device_count():
            torch.cuda.set_rng_state_all(cuda)
        _set_rng_state(json.loads(meta["rng"]))
    return meta


def last_checkpoint(out_dir: str | Path) -> Path | None:
    """The checkpoint of the highest step under OUT/checkpoints, or None."""
    found = sorted(Path(out_dir, CHECKPOINT_DIR).glob("step-*.safetensors"))
    return found[-1] if found else None


# -- the loop ----------------------------------------------------------------------------------

LossFn = Callable[[torch.nn.Module, Any, torch.device], torch.Tensor]


def default_collate(items: list[Any]) -> Any:
    from torch.utils.data import default_collate as collate

    return collate(items)


def train_loop(model: torch.nn.Module, loss_fn: LossFn, dataset: Any, out_dir: str | Path,
               cfg: TrainConfig, *, seed: int = 0, device: str | torch.device = "auto",
               resume: bool = True, progress: bool = True,
               collate: Callable[[list[Any]], Any] = default_collate,
               optimizer: torch.optim.Optimizer | None = None,
               stop_after: int | None = None, prefetch: bool | None = False) -> TrainResult:
    """Train `model` for cfg.steps optimizer steps over `dataset` (anything with len and
    [i]; a step's items come from one `__getitems__` call where it has one, as DataLoader
    reads them); `loss_fn(model, batch, device)` returns the scalar loss of a collated batch.

    Writes OUT/checkpoints/step-NNNNNNNN.safetensors every cfg.checkpoint_every steps (keeping
    the last cfg.keep_checkpoints) and OUT/checkpoint.safetensors at the end. With `resume`, the
    last step checkpoint is loaded first. `stop_after=k` returns after step k without the final
    checkpoint, as if the process had been killed there (for tests). `prefetch`: read the next
    step's batch in a thread while this step computes (None: on CUDA only, where the GPU would
    otherwise wait for the CPU; on a CPU both share the same cores). It pays only where reading
    is a good share of a step: on an H100 it cut TimeSformer-base's step from 0.325 to 0.244 s,
    but made ResNet-50's, whose cached crops read in under 1 % of it, 1.5x slower (0.096 to
    0.147 s; benchmarks/gpu.py). The batches, and so the weights, are the same either way: a
    batch depends only on the step.
    """
    import torch.distributed as dist

    out = Path(out_dir)
    dev = resolve_device(device)
    distributed = init_distributed(dev)
    rank, world = dist_env() if distributed else (0, 1)
    if cfg.batch_size % world:
        raise ValueError(f"batch_size {cfg.batch_size} is not a multiple of {world} processes")
    deterministic(cfg.threads)
    seed_everything(seed)
    model.to(dev)
    if optimizer is None:
        optimizer = torch.optim.AdamW(model.parameters(), lr=cfg.lr,
                                      weight_decay=cfg.weight_decay)
    use_amp = cfg.amp and dev.type == "cuda"
    amp_dtype = torch.bfloat16 if use_amp and torch.cuda.is_bf16_supported() else torch.float16
    scaler = torch.amp.GradScaler("cuda") if use_amp and amp_dtype == torch.float16 else None

    start = 0
    ckpt = last_checkpoint(out) if resume else None
    if ckpt is not None:
        meta = load_checkpoint(ckpt, model, optimizer, scaler, restore_rng=True)
        start = int(meta["step"])
    net: torch.nn.Module = model
    if distributed:
        from torch.nn.parallel import DistributedDataParallel

        net = DistributedDataParallel(model, device_ids=[dev.index] if dev.type == "cuda"
                                      else None)
    base_lrs = [g["lr"] for g in optimizer.param_groups]
    meta_extra = {"config": asdict(cfg), "seed": seed, "world_size": world}

    losses: list[float] = []
    bar = None
    if progress and rank == 0:
        from .progress import progress_bar

        bar = progress_bar()
        bar.start()
        task = bar.add_task("training", total=cfg.steps, completed=start)
    net.train()

    def fetch(step: int) -> Any:
        return collate(read_items(dataset, batch_indices(len(dataset), step, cfg.batch_size,
                                                         seed, rank, world)))

    ahead = dev.type == "cuda" if prefetch is None else prefetch
    pool = ThreadPoolExecutor(1, "vtsbench-prefetch") if ahead else None
    pending = pool.submit(fetch, start) if pool is not None and start < cfg.steps else None
    try:
        for step in range(start, cfg.steps):
            for g, base in zip(optimizer.param_groups, base_lrs, strict=True):
                g["lr"] = base * lr_factor(step, cfg)
            batch = fetch(step) if pending is None else pending.result()
            if pool is not None and step + 1 < cfg.steps:
                pending = pool.submit(fetch, step + 1)
            optimizer.zero_grad(set_to_none=True)
            with torch.autocast(device_type=dev.type, dtype=amp_dtype, enabled=use_amp):
                loss = loss_fn(net, batch, dev)
            if scaler is not None:
                scaler.scale(loss).backward()
                scaler.unscale_(optimizer)
            else:
                loss.backward()
            if cfg.grad_clip:
                torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.grad_clip)
            if scaler is not None:
                scaler.step(optimizer)
                scaler.update()
            else:
                optimizer.step()
            losses.append(float(loss.detach()))
            done = step + 1
            if bar is not None:
                bar.update(task, completed=done, description=f"training loss {losses[-1]:.4f}")
            if done % cfg.checkpoint_every == 0 and done < cfg.steps and rank == 0:
                for g, base in zip(optimizer.param_groups, base_lrs, strict=True):
                    g["lr"] = base
                save_checkpoint(out / CHECKPOINT_DIR / f"step-{done:08d}.safetensors", model,
                                optimizer, done, scaler, {**meta_extra, **cfg.extra})
                old = sorted((out / CHECKPOINT_DIR).glob("step-*.safetensors"))
                for p in old[:-cfg.keep_checkpoints]:
                    p.unlink()
            if stop_after is not None and done >= stop_after:
                return TrainResult(model, done, out / CHECKPOINT_DIR, start, losses)
    finally:
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)
        if bar is not None:
            bar.stop()
    for g, base in zip(optimizer.param_groups, base_lrs, strict=True):
        g["lr"] = base
    final = out / FINAL
    if rank == 0:
        save_checkpoint(final, model, optimizer, cfg.steps, scaler, {**meta_extra, **cfg.extra})
    if distributed:
        dist.barrier()
    return TrainResult(model, cfg.steps, final, start, losses)
