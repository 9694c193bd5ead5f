"""Input checks shared by every public entry point.

Each check raises ``ValueError`` or ``TypeError`` naming the argument and the value seen;
nothing is clamped or repaired. Checks that need the tensor's values (negative counts,
NaN, integer-valued counts) reduce on the tensor's own device and synchronise once per
call, at the public boundary, never inside a loop.
"""

from __future__ import annotations

import contextlib
import contextvars
import math
from collections.abc import Iterator, Sequence
from typing import Callable

import torch
from torch import Tensor

__all__ = [
    "check_frames",
    "as_batch",
    "is_integer_valued",
    "check_integer_valued",
    "per_sample",
    "check_fraction",
    "check_generator",
]

# True while a module runs on frames whose values it has already checked: the kernels it
# calls (and nested containers) then skip the value pass, so a call reads its input for
# validation once, not once per kernel.
_VALUES_CHECKED: contextvars.ContextVar[bool] = contextvars.ContextVar("values_checked", default=False)


@contextlib.contextmanager
def values_checked() -> Iterator[None]:
    """Within this block ``check_frames`` checks shapes and dtypes but not values again."""
    token = _VALUES_CHECKED.set(True)
    try:
        yield
    finally:
        _VALUES_CHECKED.reset(token)


_INTEGER_DTYPES = {torch.uint8, torch.int8, torch.int16, torch.int32, torch.int64}


def _describe(x: object) -> str:
    if isinstance(x, Tensor):
        return f"tensor of shape {tuple(x.shape)} and dtype {x.dtype}"
    return repr(x)


def check_frames(frames: object, name: str = "frames", *, check_values: bool = True) -> Tensor:
    """Check an event-frame tensor (T, 2, H, W) or (B, T, 2, H, W) and return it.

    Raises:
        TypeError: not a tensor, or a bool/complex dtype.
        ValueError: wrong rank, polarity axis not 2, negative counts or NaN/Inf.
    """
    if not isinstance(frames, Tensor):
        raise TypeError(f"{name} must be a torch.Tensor, got {type(frames).__name__}")
    if frames.dtype == torch.bool or frames.is_complex():
        raise TypeError(f"{name} must hold integer or float event counts, got dtype {frames.dtype}")
    if frames.dim() not in (4, 5) or frames.shape[-3] != 2:
        raise ValueError(
            f"{name}: expected (T, 2, H, W) or (B, T, 2, H, W), got {tuple(frames.shape)}"
        )
    if check_values and frames.numel() > 0 and frames.dtype != torch.uint8 and not _VALUES_CHECKED.get():
        # one pass over the data: the minimum is NaN if any value is, and the maximum
        # is +Inf if any value is.
        low, high = torch.aminmax(frames)
        finite, negative = torch.stack(
            [torch.isfinite(low) & torch.isfinite(high), low < 0]
        ).tolist()  # a single host sync for both checks
        if not finite:
            raise ValueError(f"{name} must be finite, got NaN or Inf values")
        if negative:
            raise ValueError(
                f"{name} must hold non-negative event counts, got minimum {low.item()}"
            )
    return frames


def as_batch(frames: Tensor) -> tuple[Tensor, Callable[[Tensor], Tensor]]:
    """View (T, 2, H, W) as (1, T, 2, H, W); return the view and a function undoing it."""
    if frames.dim() == 4:
        return frames.unsqueeze(0), lambda out: out.squeeze(0)
    return frames, lambda out: out


def is_integer_valued(frames: Tensor) -> bool:
    """True when every value is a whole number (always true for integer dtypes)."""
    if frames.dtype in _INTEGER_DTYPES or frames.numel() == 0:
        return True
    return bool((frames == torch.round(frames)).all())


def check_integer_valued(frames: Tensor, name: str, hint: str) -> None:
    """Raise ``ValueError`` when ``frames`` holds non-integer counts."""
    if not is_integer_valued(frames):
        bad = frames[frames != torch.round(frames)].flatten()[0].item()
        raise ValueError(f"{name} must hold integer-valued event counts, got {bad!r}; {hint}")


def per_sample(
    value: float | int | Sequence[float] | Tensor,
    batch: int,
    name: str,
    *,
    dtype: torch.dtype = torch.float64,
    device: torch.device | str | None = None,
) -> Tensor:
    """Turn a scalar or a (B,) sequence/tensor into a (B,) tensor on ``device``.

    Raises:
        TypeError: not a number, sequence or tensor.
        ValueError: a tensor/sequence whose length is not the batch size, or NaN.
    """
    if isinstance(value, bool):
        raise TypeError(f"{name} must be a number or a (B,) tensor, got {value!r}")
    if isinstance(value, (int, float)):
        out = torch.full((batch,), value, dtype=dtype)
    elif isinstance(value, (Tensor, Sequence)):
        out = torch.as_tensor(value)
        if out.dtype == torch.bool or out.is_complex():
            raise TypeError(f"{name} must be real numbers, got dtype {out.dtype}")
        if out.dim() == 0:
            out = out.expand(batch)
        if out.dim() != 1 or out.shape[0] != batch:
            raise ValueError(
                f"{name} must be a scalar or have shape ({batch},) to match the batch, "
                f"got {_describe(value)}"
            )
        out = out.to(dtype)
    else:
        raise TypeError(
            f"{name} must be a number or a (B,) tensor, got {type(value).__name__}"
        )
    if out.is_floating_point() and out.numel() and bool(torch.isnan(out).any()):
        raise ValueError(f"{name} must not be NaN, got {_describe(value)}")
    return out.to(device) if device is not None else out


def check_fraction(fraction: Tensor, name: str = "fraction") -> None:
    """Raise ``ValueError`` unless every entry lies in [0, 1]."""
    if fraction.numel() and bool(((fraction < 0) | (fraction > 1)).any()):
        raise ValueError(f"{name} must lie in [0, 1], got {fraction.tolist()}")


def check_generator(generator: object, device: torch.device, name: str = "generator") -> None:
    """Raise unless ``generator`` is ``None`` or a ``torch.Generator`` on ``device``."""
    if generator is None:
        return
    if not isinstance(generator, torch.Generator):
        raise TypeError(f"{name} must be a torch.Generator or None, got {type(generator).__name__}")
    if torch.device(generator.device).type != torch.device(device).type:
        raise ValueError(
            f"{name} lives on {generator.device} but the frames live on {device}; "
            "random kernels need a generator on the frames' device"
        )


def check_number(value: object, name: str, *, low: float = -math.inf, high: float = math.inf) -> float:
    """Check a real scalar within [low, high] and return it as float."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TypeError(f"{name} must be a real number, got {value!r}")
    if not (low <= value <= high) or math.isnan(value):
        raise ValueError(f"{name} must lie in [{low}, {high}], got {value!r}")
    return float(value)
