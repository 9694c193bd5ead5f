"""Process orchestration of a protocol run: local ranks, ``torchrun`` groups, worker errors.

A run's work units are spread over ranks joined by :mod:`torch.distributed`: gloo on the
CPU, nccl on GPUs. :func:`spawn` starts ``jobs`` local ranks itself (``--jobs``);
:func:`join_from_env` joins the group ``torchrun`` describes. A spawned worker asks the
kernel to stop it when its parent dies (``PR_SET_PDEATHSIG`` on Linux), so a killed
``reproduce`` leaves no training processes behind, and an exception inside a worker reaches
the caller as itself (its type and message), not as the "connection closed" error of the
ranks left waiting for it.
"""

from __future__ import annotations

import os
import pickle
import socket
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ._files import atomic_write

__all__ = ["spawn", "join_from_env", "current_group", "gather_to_rank0", "broadcast_from_rank0"]


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _die_with_parent() -> None:
    """On Linux, have the kernel stop this worker when its parent dies (``PR_SET_PDEATHSIG``)."""
    if sys.platform.startswith("linux"):
        import ctypes
        import signal

        try:
            ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM))  # 1 = PR_SET_PDEATHSIG
        except (OSError, AttributeError):  # pragma: no cover - no prctl: nothing to do
            pass


def _record(errors: str, rank: int, error: BaseException) -> None:
    """Keep a worker's own exception where the parent can read it back."""
    try:
        payload = pickle.dumps(error)
        pickle.loads(payload)
    except Exception:  # an exception that does not pickle: keep its type name and message
        payload = pickle.dumps(RuntimeError(f"{type(error).__name__}: {error}"))
    path = Path(errors) / f"rank-{rank}.pickle"
    with atomic_write(path, "wb") as handle:
        handle.write(payload)


def _recorded(errors: str) -> BaseException | None:
    """The exception of the lowest rank that recorded one, or ``None``."""
    paths = sorted(Path(errors).glob("rank-*.pickle"), key=lambda p: int(p.stem.split("-")[1]))
    for path in paths:
        try:
            return pickle.loads(path.read_bytes())
        except Exception:  # pragma: no cover - a half-written file: try the next rank
            continue
    return None


def _spawned(rank: int, world: int, port: int, work: Callable[..., None], arguments: tuple, errors: str) -> None:
    """Entry point of a ``--jobs`` worker: join the gloo group, work, wait for the others."""
    import torch.distributed as dist

    _die_with_parent()
    dist.init_process_group("gloo", init_method=f"tcp://127.0.0.1:{port}", rank=rank, world_size=world)
    try:
        try:
            work(rank, world, *arguments)
        except BaseException as error:
            _record(errors, rank, error)
            raise
        dist.barrier()
    finally:
        dist.destroy_process_group()


def spawn(work: Callable[..., None], arguments: tuple, jobs: int) -> None:
    """Run ``work(rank, jobs, *arguments)`` in ``jobs`` local processes joined by gloo.

    ``work`` must be a module-level function (it is pickled to the workers). If a worker
    raises, the others are stopped and the worker's own exception is raised here (the
    lowest rank's, if several failed on their own).
    """
    import torch.multiprocessing as mp

    with tempfile.TemporaryDirectory(prefix="event-transforms-workers-") as errors:
        try:
            mp.spawn(_spawned, args=(jobs, _free_port(), work, arguments, errors), nprocs=jobs, join=True)
        except Exception:
            raised = _recorded(errors)
            if raised is None:
                raise
            raise raised from None


def join_from_env(device: str) -> bool:
    """Join the process group ``torchrun`` describes (``WORLD_SIZE`` > 1); True if joined.

    The backend is nccl for ``device="cuda"`` (each rank on GPU ``LOCAL_RANK``), else gloo.
    """
    if int(os.environ.get("WORLD_SIZE", "1")) <= 1:
        return False
    import torch
    import torch.distributed as dist

    if not dist.is_initialized():
        backend = "nccl" if device == "cuda" else "gloo"
        if backend == "nccl":
            torch.cuda.set_device(int(os.environ.get("LOCAL_RANK", "0")))
        dist.init_process_group(backend)
    return True


def current_group() -> tuple[int, int] | None:
    """``(rank, world size)`` of an initialised process group, or ``None``."""
    import torch.distributed as dist

    if dist.is_available() and dist.is_initialized():
        return dist.get_rank(), dist.get_world_size()
    return None


def gather_to_rank0(mine: dict[str, Any]) -> dict[str, Any] | None:
    """Wait for every rank, then merge every rank's dict on rank 0 (``None`` on the others)."""
    import torch.distributed as dist

    dist.barrier()
    rank, world = dist.get_rank(), dist.get_world_size()
    if rank != 0:
        dist.gather_object(mine, None, dst=0)
        return None
    gathered: list[Any] = [None] * world
    dist.gather_object(mine, gathered, dst=0)
    return {k: v for part in gathered for k, v in part.items()}


def broadcast_from_rank0(obj: Any) -> Any:
    """Rank 0's ``obj`` on every rank of the initialised group."""
    import torch.distributed as dist

    box = [obj]
    dist.broadcast_object_list(box, src=0)
    return box[0]
