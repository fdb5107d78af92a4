"""Start-up time of the command line: `vtsbench --version` (what every command pays before its
work), `--help` and a command's help against `python -c pass` (the floor any Python command
pays), alternated in one run so machine noise hits them alike.

    .venv/bin/python benchmarks/cli_start.py --repeat 10
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time

from machine import machine  # benchmarks/machine.py: the shared machine line

COMMANDS = {
    "python -c pass": [sys.executable, "-c", "pass"],
    "vtsbench --version": [sys.executable, "-m", "vtsbench", "--version"],  # no help drawn
    "vtsbench --help": [sys.executable, "-m", "vtsbench", "--help"],
    "vtsbench build -h": [sys.executable, "-m", "vtsbench", "build", "-h"],
}


def wall(cmd: list[str]) -> float:
    """Seconds one run of a command takes, output discarded."""
    t0 = time.perf_counter()
    subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=10, help="Runs of each command.")
    args = ap.parse_args()
    for cmd in COMMANDS.values():  # warm the file cache
        wall(cmd)
    times: dict[str, list[float]] = {k: [] for k in COMMANDS}
    for _ in range(args.repeat):
        for name, cmd in COMMANDS.items():
            times[name].append(wall(cmd))
    print(machine())
    base = statistics.median(times["python -c pass"])
    print(f"{'command':<20} {'best s':>8} {'median s':>9} {'x python':>9}")
    for name, ts in times.items():
        med = statistics.median(ts)
        print(f"{name:<20} {min(ts):8.3f} {med:9.3f} {med / base:9.1f}")


if __name__ == "__main__":
    main()
