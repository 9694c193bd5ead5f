"""What a result depends on besides the code: :func:`environment` (package, commit, torch, CPU
model and kernel set, threads, device) and :func:`git_commit`."""

from __future__ import annotations

import os
import platform
from pathlib import Path
from typing import Any

import torch

__all__ = ["environment", "git_commit"]


def _cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``; ``platform.processor()`` elsewhere)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def environment(device: str = "cpu", threads: int | None = None) -> dict[str, Any]:
    """What a result depends on besides the code: package version and commit, torch, the CPU
    model and the kernel set torch dispatches to (``ATEN_CPU_CAPABILITY``, and what
    ``torch.backends.cpu.get_cpu_capability()`` reports), threads and device. The same code
    under another kernel set gives per-seed MSEs that differ in the last digits, and training
    amplifies that: compare verdicts (sign, significance) across machines, not digits."""
    from ... import __version__

    try:
        capability = torch.backends.cpu.get_cpu_capability()
    except (AttributeError, RuntimeError):  # pragma: no cover - older torch
        capability = "unknown"
    return {
        "package_version": __version__,
        "commit": git_commit(),
        "torch": torch.__version__,
        "cpu_model": _cpu_model(),
        "cpu_capability": capability,
        "ATEN_CPU_CAPABILITY": os.environ.get("ATEN_CPU_CAPABILITY"),
        "threads": threads if threads is not None else torch.get_num_threads(),
        "device": str(device),
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "cuda": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None,
    }


def git_commit() -> str:
    """The package checkout's ``git rev-parse HEAD`` (``-dirty`` when tracked files differ from
    it), or ``"unknown"`` outside a git checkout."""
    import subprocess

    where = Path(__file__).resolve().parents[1]  # the application folder, event_transforms/tactile
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=where, capture_output=True, text=True, timeout=10)
        if head.returncode != 0:
            return "unknown"
        dirty = subprocess.run(["git", "diff", "--quiet", "HEAD", "--", "."], cwd=where, timeout=10).returncode
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return head.stdout.strip() + ("-dirty" if dirty == 1 else "")
