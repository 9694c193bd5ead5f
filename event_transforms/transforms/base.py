"""The base class every transform module derives from, and parameter-sampling helpers.

A module holds settings. ``make_params`` draws the per-sample parameters of one call as
(B,) tensors on the CPU (so CPU and CUDA runs draw the same numbers); ``apply`` hands them
to a pure kernel from :mod:`event_transforms.functional` on the frames' device. ``forward``
is not overridden by subclasses: it checks the input's rank, views one sequence as a batch
of one, keeps a ``torchvision.tv_tensors.Video`` a ``Video``, and lets a caller replay a
draw with ``params=``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Callable

import torch
from torch import Tensor, nn

from .._validation import as_batch, check_frames, values_checked

__all__ = ["EventTransform", "Params", "apply_by_group"]

Params = dict[str, Tensor]


def _video_type() -> type | None:
    try:
        from torchvision import tv_tensors
    except ImportError:  # pragma: no cover - torchvision is a dependency
        return None
    return tv_tensors.Video


class EventTransform(nn.Module):
    """Base class: an ``nn.Module`` mapping event frames to event frames.

    Subclasses override :meth:`make_params` (draw per-sample parameters, CPU, no state)
    and :meth:`apply` (call a kernel). Calling the module accepts ``(T, 2, H, W)`` or
    ``(B, T, 2, H, W)`` frames and returns the same layout on the same device.
    """

    def forward(
        self,
        frames: Tensor,
        *,
        generator: torch.Generator | None = None,
        params: Params | None = None,
    ) -> Tensor:
        """Transform ``frames``.

        Args:
            frames: event counts, ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
            generator: source of randomness; ``None`` uses torch's global RNG, so each
                DataLoader worker draws differently.
            params: parameters returned by :meth:`make_params`, to replay a draw.
        """
        check_frames(frames)  # values once here; kernels inside skip them
        video = _video_type()
        like = frames if video is not None and isinstance(frames, video) else None
        if like is not None:
            frames = frames.as_subclass(Tensor)
        batch, unbatch = as_batch(frames)
        if params is None:
            params = self.make_params(batch.shape[0], generator=generator)
        with values_checked():
            out = unbatch(self.apply(batch, params, generator=generator))
        if like is not None:
            from torchvision import tv_tensors

            out = tv_tensors.wrap(out, like=like)
        return out

    def make_params(self, batch_size: int, *, generator: torch.Generator | None = None) -> Params:
        """Draw this call's per-sample parameters as (B,) CPU tensors."""
        return {}

    def apply(
        self, frames: Tensor, params: Params, *, generator: torch.Generator | None = None
    ) -> Tensor:  # pragma: no cover - abstract
        """Apply the transform to a batch ``(B, T, 2, H, W)`` with given parameters."""
        raise NotImplementedError


# --------------------------------------------------------------------------- sampling


def _sample_device(generator: torch.Generator | None) -> torch.device:
    return torch.device("cpu") if generator is None else torch.device(generator.device)


def uniform(
    low: float, high: float, batch_size: int, generator: torch.Generator | None
) -> Tensor:
    """``batch_size`` draws from U[low, high) as a float64 CPU tensor."""
    u = torch.rand(
        batch_size, generator=generator, device=_sample_device(generator), dtype=torch.float64
    )
    return (low + (high - low) * u).cpu()


def choice(values: Sequence[Any] | Tensor, batch_size: int, generator: torch.Generator | None) -> Tensor:
    """``batch_size`` uniform draws from ``values`` (a 1-D tensor or sequence), on the CPU."""
    values = torch.as_tensor(values)
    index = torch.randint(
        len(values), (batch_size,), generator=generator, device=_sample_device(generator)
    ).cpu()
    return values[index]


def bernoulli(p: float, batch_size: int, generator: torch.Generator | None) -> Tensor:
    """``batch_size`` Bernoulli(p) draws as a bool CPU tensor."""
    return uniform(0.0, 1.0, batch_size, generator) < p


def check_range(
    value: float | Sequence[float], name: str, *, symmetric: bool = False, low: float | None = None
) -> tuple[float, float]:
    """Turn ``x`` (``(-x, x)`` if ``symmetric``) or ``(a, b)`` into a checked ``(a, b)``."""
    if isinstance(value, bool):
        raise TypeError(f"{name} must be a number or a (min, max) pair, got {value!r}")
    if isinstance(value, (int, float)):
        if not symmetric:
            raise TypeError(f"{name} must be a (min, max) pair, got {value!r}")
        if value < 0:
            raise ValueError(f"{name} as a single number must be non-negative, got {value!r}")
        pair = (-float(value), float(value))
    elif isinstance(value, Sequence) and len(value) == 2 and all(
        isinstance(v, (int, float)) and not isinstance(v, bool) for v in value
    ):
        pair = (float(value[0]), float(value[1]))
    else:
        raise TypeError(f"{name} must be a number or a (min, max) pair, got {value!r}")
    if pair[0] > pair[1] or any(v != v for v in pair):
        raise ValueError(f"{name} must satisfy min <= max, got {value!r}")
    if low is not None and pair[0] < low:
        raise ValueError(f"{name} must be >= {low}, got {value!r}")
    return pair


# --------------------------------------------------------------------------- groups

GroupFn = Callable[[Tensor, Tensor], Tensor]


def apply_by_group(frames: Tensor, group: Tensor, functions: Sequence[GroupFn | None]) -> Tensor:
    """Apply ``functions[g]`` to the samples whose ``group`` is ``g``; ``None`` keeps them.

    Each function gets the sub-batch and the (CPU) indices of its samples, and is called
    even on an empty sub-batch, so the output dtype (promoted over every branch) does not
    depend on the random draw. Samples are gathered once per group, not looped over.

    Args:
        frames: batch ``(B, T, 2, H, W)``.
        group: ``(B,)`` integer CPU tensor with values in ``[0, len(functions))``.
        functions: one callable ``(sub_batch, indices) -> sub_batch`` or ``None`` per group.
    """
    device = frames.device
    results: list[tuple[Tensor, Tensor]] = []
    out_dtype = frames.dtype if any(f is None for f in functions) else None
    for g, function in enumerate(functions):
        if function is None:
            continue
        index = (group == g).nonzero().squeeze(1)
        if index.numel() == frames.shape[0]:
            sub = frames  # the whole batch: no gather
        else:
            sub = frames.index_select(0, index.to(device))
        result = function(sub, index)
        out_dtype = result.dtype if out_dtype is None else torch.promote_types(out_dtype, result.dtype)
        results.append((index, result))
    assert out_dtype is not None  # at least one group is a function or None
    for index, result in results:
        if index.numel() == frames.shape[0]:
            return result.to(out_dtype)
    out = frames.to(out_dtype, copy=True)
    for index, result in results:
        if index.numel():
            out.index_copy_(0, index.to(device), result.to(out_dtype))
    return out
