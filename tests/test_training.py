"""The generic training loop: exact resume, safetensors checkpoints, DDP with gloo on CPU."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

torch = pytest.importorskip("torch")

from tests.fixtures.data import ROOT  # noqa: E402
from tests.fixtures.training import CFG, ce, tiny_data, tiny_model  # noqa: E402
from vtsbench.training import (  # noqa: E402
    batch_indices,
    last_checkpoint,
    load_checkpoint,
    save_checkpoint,
    train_loop,
)


def weights(model: torch.nn.Module) -> dict[str, torch.Tensor]:
    return {k: v.detach().clone() for k, v in model.state_dict().items()}


def test_batches_are_seeded_and_ranks_partition() -> None:
    a = batch_indices(10, 3, 4, seed=0)
    assert a == batch_indices(10, 3, 4, seed=0)
    assert a != batch_indices(10, 3, 4, seed=1)
    r0, r1 = batch_indices(10, 3, 4, 0, 0, 2), batch_indices(10, 3, 4, 0, 1, 2)
    assert sorted(r0 + r1) == sorted(a)
    # one epoch visits every sample once
    seen = [i for s in range(3) for i in batch_indices(12, s, 4, 0)]
    assert sorted(seen) == list(range(12))


def test_resume_after_kill_gives_bit_identical_weights(tmp_path: Path) -> None:
    full = train_loop(tiny_model(), ce, tiny_data(), tmp_path / "full", CFG, seed=7,
                      device="cpu", progress=False)
    # "killed" after step 7: the last checkpoint is step 5, steps 6-7 are lost
    part = train_loop(tiny_model(), ce, tiny_data(), tmp_path / "cut", CFG, seed=7,
                      device="cpu", progress=False, stop_after=7)
    assert part.step == 7 and last_checkpoint(tmp_path / "cut").name == "step-00000005.safetensors"
    resumed = train_loop(tiny_model(), ce, tiny_data(), tmp_path / "cut", CFG, seed=7,
                         device="cpu", progress=False)
    assert resumed.resumed_from == 5
    a, b = weights(full.model), weights(resumed.model)
    assert a.keys() == b.keys()
    for k in a:
        assert torch.equal(a[k], b[k]), k
    assert full.losses[-3:] == resumed.losses[-3:]
    # the final checkpoints hold the same weights too
    m1, m2 = tiny_model(), tiny_model()
    load_checkpoint(full.checkpoint, m1)
    load_checkpoint(resumed.checkpoint, m2)
    for (k, v1), v2 in zip(m1.state_dict().items(), m2.state_dict().values(), strict=True):
        assert torch.equal(v1, v2), k
    # and differ from another seed
    other = train_loop(tiny_model(), ce, tiny_data(), tmp_path / "other", CFG, seed=8,
                       device="cpu", progress=False)
    assert any(not torch.equal(a[k], weights(other.model)[k]) for k in a)


def test_prefetch_reads_the_same_batches_and_resumes_exactly(tmp_path: Path) -> None:
    """The next batch read in a thread (the CUDA default) trains the same weights as reading it
    in the loop, also across a kill and a resume, and reads each step's batch once."""
    reads: list[int] = []

    class Counted(list):
        """tiny_data, counting the items read."""

        def __getitem__(self, i):  # type: ignore[override]
            reads.append(i)
            return super().__getitem__(i)

    plain = train_loop(tiny_model(), ce, tiny_data(), tmp_path / "plain", CFG, seed=7,
                       device="cpu", progress=False, prefetch=False)
    ahead = train_loop(tiny_model(), ce, Counted(tiny_data()), tmp_path / "ahead", CFG, seed=7,
                       device="cpu", progress=False, prefetch=True)
    assert len(reads) == CFG.steps * CFG.batch_size
    cut = train_loop(tiny_model(), ce, tiny_data(), tmp_path / "cut", CFG, seed=7,
                     device="cpu", progress=False, prefetch=True, stop_after=7)
    assert cut.step == 7
    resumed = train_loop(tiny_model(), ce, tiny_data(), tmp_path / "cut", CFG, seed=7,
                         device="cpu", progress=False, prefetch=True)
    assert plain.losses == ahead.losses
    for res in (ahead, resumed):
        a, b = weights(plain.model), weights(res.model)
        assert all(torch.equal(a[k], b[k]) for k in a)


def test_checkpoint_is_safetensors_with_optimizer_and_rng(tmp_path: Path) -> None:
    from safetensors import safe_open

    model = tiny_model()
    opt = torch.optim.AdamW(model.parameters(), lr=1e-3)
    ce(model, (torch.randn(4, 6), torch.tensor([0, 1, 0, 1])), "cpu").backward()
    opt.step()
    path = save_checkpoint(tmp_path / "c.safetensors", model, opt, step=3,
                           metadata={"note": "x"})
    with safe_open(str(path), framework="pt") as fh:
        keys = set(fh.keys())
        meta = fh.metadata()
    assert {"model.0.weight", "optim.0.exp_avg", "optim.0.step", "rng.torch"} <= keys
    assert meta["step"] == "3" and meta["note"] == "x"
    assert b"pickle" not in path.read_bytes()[:64]
    m2 = tiny_model()
    opt2 = torch.optim.AdamW(m2.parameters(), lr=1e-3)
    load_checkpoint(path, m2, opt2)
    assert torch.equal(m2[0].weight, model[0].weight)
    s1, s2 = opt.state_dict(), opt2.state_dict()
    assert s1["param_groups"] == s2["param_groups"]
    for pid in s1["state"]:
        for k, v in s1["state"][pid].items():
            assert torch.equal(v, s2["state"][pid][k])


DDP_SCRIPT = textwrap.dedent("""
    import sys, torch
    sys.path.insert(0, {root!r})
    from tests.fixtures.training import CFG, ce, tiny_data, tiny_model
    from vtsbench.training import train_loop, dist_env
    import dataclasses
    cfg = dataclasses.replace(CFG, steps=6, checkpoint_every=4)
    res = train_loop(tiny_model(), ce, tiny_data(), {out!r}, cfg, seed=3, device="cpu",
                     progress=False)
    rank, world = dist_env()
    assert world == 2
    torch.save({{k: v for k, v in res.model.state_dict().items()}},
               {out!r} + f"/rank{{rank}}.pt")
""")


def test_ddp_gloo_two_processes_agree(tmp_path: Path) -> None:
    out = tmp_path / "ddp"
    out.mkdir()
    script = tmp_path / "ddp_run.py"
    script.write_text(DDP_SCRIPT.format(root=str(ROOT), out=str(out)))
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--standalone",
                           "--nproc_per_node", "2", str(script)], capture_output=True,
                          text=True, timeout=120, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    w0 = torch.load(out / "rank0.pt", weights_only=True)
    w1 = torch.load(out / "rank1.pt", weights_only=True)
    start = tiny_model().state_dict()
    for k in w0:
        assert torch.equal(w0[k], w1[k]), k
    assert any(not torch.equal(w0[k], start[k]) for k in w0)  # it did train
    assert (out / "checkpoint.safetensors").is_file()
    assert last_checkpoint(out).name == "step-00000004.safetensors"


KILL_SCRIPT = textwrap.dedent("""
    import sys, time, torch
    sys.path.insert(0, {root!r})
    from tests.fixtures.training import CFG, ce, tiny_data, tiny_model
    from vtsbench.training import train_loop

    def slow(model, batch, device):
        time.sleep(0.2)
        return ce(model, batch, device)

    train_loop(tiny_model(), slow, tiny_data(), {out!r}, CFG, seed=7, device="cpu",
               progress=False)
""")


def test_sigkill_then_resume_matches_uninterrupted(tmp_path: Path) -> None:
    import signal
    import time

    out = tmp_path / "killed"
    script = tmp_path / "kill_run.py"
    script.write_text(KILL_SCRIPT.format(root=str(ROOT), out=str(out)))
    proc = subprocess.Popen([sys.executable, str(script)],
                            env={**os.environ, "OMP_NUM_THREADS": "1"})
    try:
        deadline = time.monotonic() + 60
        while last_checkpoint(out) is None and time.monotonic() < deadline:
            assert proc.poll() is None, "the run ended before its first checkpoint"
            time.sleep(0.02)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    assert not (out / "checkpoint.safetensors").exists()
    resumed = train_loop(tiny_model(), ce, tiny_data(), out, CFG, seed=7, device="cpu",
                         progress=False)
    assert resumed.resumed_from == 5
    full = train_loop(tiny_model(), ce, tiny_data(), tmp_path / "full", CFG, seed=7,
                      device="cpu", progress=False)
    for k, v in weights(full.model).items():
        assert torch.equal(v, resumed.model.state_dict()[k]), k
