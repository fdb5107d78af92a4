"""The machine line every benchmark prints: cores, CPU model, library versions, load."""

from __future__ import annotations

import os
import platform
from pathlib import Path


def cpu_model() -> str:
    """CPU model from /proc/cpuinfo where there is one, else what platform knows."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine() -> str:
    """Cores, CPU model, Python, numpy, scipy and torch (threads, CUDA), and the load average."""
    import numpy as np
    import scipy

    text = (f"{os.cpu_count()} cores, {cpu_model()}; Python {platform.python_version()}, "
            f"numpy {np.__version__}, scipy {scipy.__version__}")
    try:
        import torch

        text += f", torch {torch.__version__} ({torch.get_num_threads()} threads)"
        text += f", CUDA {torch.cuda.get_device_name(0)}" if torch.cuda.is_available() \
            else ", no GPU"
    except ImportError:
        text += ", no torch"
    if hasattr(os, "getloadavg"):
        text += f"; load average {os.getloadavg()[0]:.1f} at the end"
    return text
