"""The numpy solvers leave nothing behind that can hang a later fork (a DataLoader's workers)."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest
import scipy.fft

from vtsbench.depth import poisson


@pytest.mark.parametrize("shape", [(48, 64), (5, 48, 64), (2, 3, 24, 32)])
@pytest.mark.parametrize("method", ["dct", "dst"])
def test_transforms_never_start_scipys_thread_pool(monkeypatch, shape, method) -> None:
    """scipy.fft with workers > 1 starts pocketfft's pool, whose fork handler can hang a fork:
    every transform here runs with workers=1, and a batch gives the same result as its frames
    one by one."""
    seen: list[object] = []
    for name in ("dctn", "idctn", "dstn", "idstn"):
        real = getattr(scipy.fft, name)

        def spy(*a, _real=real, **k):
            seen.append(k.get("workers"))
            return _real(*a, **k)

        monkeypatch.setattr(poisson.scipy.fft, name, spy)
    monkeypatch.setattr(poisson, "transform_threads", lambda: 3)  # split even on one CPU
    rng = np.random.default_rng(0)
    p, q = rng.normal(size=(2, *shape)).astype(np.float32)
    z = poisson.integrate(p, q, method=method, mm_per_px=0.05)
    assert seen and set(seen) == {1}
    flat_p, flat_q = p.reshape(-1, *shape[-2:]), q.reshape(-1, *shape[-2:])
    one_by_one = np.stack([poisson.integrate(a, b, method=method, mm_per_px=0.05)
                           for a, b in zip(flat_p, flat_q, strict=True)])
    np.testing.assert_allclose(z.reshape(one_by_one.shape), one_by_one, rtol=0, atol=1e-6)


def test_forks_in_a_row_after_a_batch_solve_do_not_hang() -> None:
    """A batch solved, then forks started one after another (as a torch DataLoader starts its
    workers), in a fresh process: every fork returns. With scipy's own threads this hung in 2
    of 6 runs of 30 s under load; here a bounded smoke check."""
    code = textwrap.dedent("""
        import os
        import numpy as np
        from vtsbench.depth.poisson import integrate
        p = np.random.default_rng(0).normal(size=(4, 60, 80)).astype(np.float32)
        for _ in range(40):
            integrate(p, p, method="dct", mm_per_px=0.05)
            pids = []
            for _ in range(4):
                pid = os.fork()
                if pid == 0:
                    os._exit(0)
                pids.append(pid)
            for pid in pids:
                os.waitpid(pid, 0)
        print("forked")
    """)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0 and "forked" in res.stdout, res.stderr
