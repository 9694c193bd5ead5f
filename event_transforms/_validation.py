"""Input checks shared by every public entry point, and the one definition of each mode set.

Each check raises ``ValueError`` or ``TypeError`` naming the argument and the value seen;
nothing is clamped or repaired. Checks run once, at the public boundary (a functional
kernel, or a module's ``forward``); private kernels behind it trust their input.

Two kinds of frame check:

- :func:`check_frames` looks at the type, dtype and shape only. It costs nothing and never
  reads the values, so it never waits for an accelerator.
- :func:`check_counts` reads the values (negative, NaN/Inf, optionally whole numbers) with
  one reduction and one host synchronisation. Kernels whose result depends on the values
  being counts (temporal event shifting, event drop, noise added to integer frames) run it
  on the entries they touch; kernels that only move or interpolate values do not.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from numbers import Integral, Real
from typing import Any

import numpy as np
import torch
from torch import Tensor

__all__ = [
    "INTERPOLATIONS",
    "TES_MODES",
    "DROP_MODES",
    "check_frames",
    "check_counts",
    "count_stats",
    "read_host",
    "on_host",
    "HOST_READ",
    "check_shape",
    "check_choice",
    "as_number",
    "check_positive",
    "check_probability",
    "check_seed",
    "check_pair",
    "check_generator",
    "as_batch",
    "check_seed",
    "describe",
]

#: Sampling modes of the interpolating warps (rotate, resize, affine).
INTERPOLATIONS = ("bilinear", "nearest")
#: How temporal event shifting chooses the moved events.
TES_MODES = ("exact", "binomial", "expected")
#: How random event drop thins the counts.
DROP_MODES = ("binomial", "expected")

#: Dtypes whose values frames may hold (torch's unsigned 16/32/64-bit types lack the
#: arithmetic the kernels need, so they are refused by name).
FRAME_DTYPES = (
    torch.uint8, torch.int8, torch.int16, torch.int32, torch.int64,
    torch.float16, torch.bfloat16, torch.float32, torch.float64,
)


#: Name of the profiler range around every read of device values on the host (see
#: :func:`read_host`): such a read waits for the device, like ``.item()``, but ``tolist``
#: on the CPU dispatches no ``aten`` op a profiler could count.
HOST_READ = "event_transforms::host_read"


def read_host(values: Tensor) -> Any:
    """``values.tolist()`` for a small tensor computed on the frames' device: the one way a
    kernel reads device numbers on the host (a host synchronisation on an accelerator),
    marked for ``torch.profiler`` so the synchronisations of a call can be counted on any
    device. Parameters drawn on the CPU are read with plain ``tolist``: no wait."""
    with torch.profiler.record_function(HOST_READ):
        return values.tolist()


def on_host(*params: Tensor | None) -> bool:
    """Whether a kernel may read its parameters on the host: they are CPU tensors (as
    ``make_params`` draws them) and no ``torch.compile`` trace is running. Otherwise (params
    already on an accelerator, e.g. for CUDA-graph capture, or compiling) kernels take
    their all-tensor path, which reads nothing on the host and gives the same result."""
    if torch.compiler.is_compiling():
        return False
    return all(p is None or p.device.type == "cpu" for p in params)


def describe(value: object) -> str:
    """A short description of ``value`` for error messages."""
    if isinstance(value, Tensor):
        if value.numel() <= 8:
            return f"tensor {value.tolist()!r} of dtype {value.dtype}"
        return f"tensor of shape {tuple(value.shape)} and dtype {value.dtype}"
    if isinstance(value, np.ndarray):
        return f"numpy array of shape {value.shape} and dtype {value.dtype}"
    return repr(value)


# --------------------------------------------------------------------------- frames


def check_frames(frames: object, name: str = "frames") -> Tensor:
    """Check that ``frames`` is event frames ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.

    Looks at the type, dtype and shape only (free, no host synchronisation).

    Raises:
        TypeError: not a tensor, or a dtype that cannot hold counts (bool, complex,
            unsigned 16/32/64-bit).
        ValueError: wrong rank, or a polarity axis that is not 2.

    Example:
        >>> check_frames(torch.zeros(36, 3, 70, 75))
        Traceback (most recent call last):
        ...
        ValueError: frames: expected (T, 2, H, W) or (B, T, 2, H, W), got (36, 3, 70, 75)
    """
    if not isinstance(frames, Tensor):
        raise TypeError(f"{name} must be a torch.Tensor, got {type(frames).__name__}")
    if frames.dtype not in FRAME_DTYPES:
        raise TypeError(
            f"{name} must hold event counts in an integer (uint8, int8, int16, int32, int64) "
            f"or float dtype, got {frames.dtype}"
        )
    if frames.dim() not in (4, 5) or frames.shape[-3] != 2:
        raise ValueError(
            f"{name}: expected (T, 2, H, W) or (B, T, 2, H, W), got {tuple(frames.shape)}"
        )
    return frames


def check_counts(values: Tensor, name: str = "frames", *, whole: str | None = None) -> None:
    """Raise unless ``values`` are finite, non-negative (and whole numbers if ``whole``).

    One reduction and one host synchronisation for any number of checks. ``whole`` is
    the hint appended to the error when a float value is not a whole number; ``None``
    skips that check. Integer dtypes skip everything but the sign.

    Example:
        >>> check_counts(torch.tensor([1.0, 2.5]), whole="use mode='expected'")
        Traceback (most recent call last):
        ...
        ValueError: frames must hold whole event counts, got 2.5; use mode='expected'
    """
    if values.numel() == 0 or values.dtype == torch.uint8:
        return
    if not values.is_floating_point():
        low = values.min()
        if bool(low < 0):
            raise ValueError(f"{name} must hold non-negative event counts, got minimum {low.item()}")
        return
    low, high = torch.aminmax(values)
    checks = [low.isfinite() & high.isfinite(), low >= 0]
    if whole is not None:
        checks.append((values == values.round()).all())
    flags = read_host(torch.stack(checks))  # one synchronisation for every check
    if not flags[0]:
        raise ValueError(f"{name} must be finite, got NaN or Inf values")
    if not flags[1]:
        raise ValueError(f"{name} must hold non-negative event counts, got minimum {low.item()}")
    if whole is not None and not flags[2]:
        bad = values[values != values.round()].flatten()[0].item()
        raise ValueError(f"{name} must hold whole event counts, got {bad!r}; {whole}")


def count_stats(
    values: Tensor, counts: Tensor, name: str = "frames", *, hint: str, extra: Sequence[Tensor] = ()
) -> list[int]:
    """Check that ``values`` are whole, non-negative, finite event counts, given ``counts =
    values.to(torch.int64)``, and read ``extra`` int64 0-d tensors, in one host
    synchronisation.

    A float value is a whole count exactly when it survives the round trip through int64
    (NaN, Inf and fractions do not), so the fast path is one comparison, one sum and one
    ``aminmax`` of the counts; the precise reason is worked out only on the error path.
    ``hint`` ends the error for fractional counts. Returns ``[largest count, *extra]``.
    """
    low, high = torch.aminmax(counts)
    parts = [low, high, *extra]
    if values.is_floating_point():
        parts.append((values != counts).sum())  # compared in the values' float dtype
    stats = read_host(torch.stack(parts))  # the one synchronisation
    if values.is_floating_point() and stats[-1]:
        check_counts(values, name, whole=hint)  # finds and names the offending value
        raise ValueError(f"{name}: counts above 2**63 per pixel are not supported")  # pragma: no cover
    if stats[0] < 0:
        raise ValueError(f"{name} must hold non-negative event counts, got minimum {stats[0]}")
    return stats[1 : 2 + len(extra)]


def check_shape(shape: object, name: str = "shape") -> torch.Size:
    """A batch shape ``(B, T, 2, H, W)`` of non-negative sizes, as ``torch.Size``."""
    if isinstance(shape, Tensor) or not isinstance(shape, Sequence) or isinstance(shape, str):
        raise TypeError(f"{name} must be a batch shape (B, T, 2, H, W), got {describe(shape)}")
    if len(shape) != 5 or any(isinstance(s, bool) or not isinstance(s, Integral) for s in shape):
        raise ValueError(f"{name} must be a batch shape (B, T, 2, H, W) of integers, got {tuple(shape)!r}")
    if any(int(s) < 0 for s in shape) or int(shape[2]) != 2:
        raise ValueError(f"{name} must be a batch shape (B, T, 2, H, W) with sizes >= 0, got {tuple(shape)!r}")
    return torch.Size(int(s) for s in shape)


def as_batch(frames: Tensor) -> tuple[Tensor, Callable[[Tensor], Tensor]]:
    """View (T, 2, H, W) as (1, T, 2, H, W); return the view and a function undoing it."""
    if frames.dim() == 4:
        return frames.unsqueeze(0), lambda out: out.squeeze(0)
    return frames, lambda out: out


# --------------------------------------------------------------------------- numbers


def as_number(
    value: object,
    name: str,
    *,
    low: float = -math.inf,
    high: float = math.inf,
    integer: bool = False,
    finite: bool = True,
) -> Any:
    """A real scalar (Python, numpy or 0-d tensor) within [low, high], as float (or int).

    Example:
        >>> as_number(np.float32(0.5), "fraction", low=0, high=1)
        0.5
        >>> as_number(torch.tensor(3), "shift", integer=True)
        3
    """
    if isinstance(value, Tensor):
        if value.dim() != 0 or value.dtype == torch.bool or value.is_complex():
            raise TypeError(f"{name} must be a real number, got {describe(value)}")
        value = value.item()
    elif isinstance(value, np.ndarray) and value.ndim == 0:
        value = value.item()
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, Real):
        raise TypeError(f"{name} must be a real number, got {value!r}")
    if integer:
        if not isinstance(value, Integral):
            if not (math.isfinite(value) and float(value).is_integer()):
                raise TypeError(f"{name} must be an integer, got {value!r}")
        number: Any = int(value)  # type: ignore[call-overload]  # a whole Real number
    else:
        number = float(value)
        if math.isnan(number) or (finite and math.isinf(number)):
            raise ValueError(f"{name} must be a finite number, got {value!r}")
    if not low <= number <= high:
        raise ValueError(f"{name} must lie in [{low}, {high}], got {value!r}")
    return number


def check_positive(value: object, name: str, *, integer: bool = False) -> Any:
    """A finite number > 0 (an int >= 1 if ``integer``)."""
    number = as_number(value, name, integer=integer)
    if number <= 0:
        raise ValueError(f"{name} must be > 0, got {value!r}")
    return number


def check_seed(seed: object, name: str = "seed") -> int:
    """A non-negative Python or NumPy integer (not a bool), as an ``int``.

    Example:
        >>> check_seed(np.int64(3))
        3
        >>> check_seed(-1)
        Traceback (most recent call last):
        ...
        ValueError: seed must be a non-negative integer, got -1
    """
    if isinstance(seed, bool) or not isinstance(seed, Integral) or seed < 0:
        raise ValueError(f"{name} must be a non-negative integer, got {seed!r}")
    return int(seed)


def check_probability(value: object, name: str = "p") -> float:
    """A probability in [0, 1]."""
    return as_number(value, name, low=0.0, high=1.0)


def check_pair(
    value: object,
    name: str,
    *,
    symmetric: bool = False,
    low: float = -math.inf,
    high: float = math.inf,
    single: bool = False,
) -> tuple[float, float]:
    """A checked ``(min, max)`` range with ``min <= max`` inside [low, high].

    A single number ``x`` means ``(-x, x)`` when ``symmetric`` (then x >= 0), or
    ``(x, x)`` when ``single``; otherwise a single number is refused.

    Example:
        >>> check_pair(45, "degrees", symmetric=True)
        (-45.0, 45.0)
        >>> check_pair((np.float64(0.1), torch.tensor(0.5)), "fraction", low=0, high=1)
        (0.1, 0.5)
    """
    scalar = isinstance(value, (Real, np.generic)) or (
        isinstance(value, (Tensor, np.ndarray)) and value.ndim == 0
    )
    if scalar:
        number = as_number(value, name)
        if symmetric:
            if number < 0:
                raise ValueError(f"{name} as a single number must be >= 0, got {value!r}")
            pair = (-number, number)
        elif single:
            pair = (number, number)
        else:
            raise TypeError(f"{name} must be a (min, max) pair, got {value!r}")
    else:
        if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, Tensor, np.ndarray)) or len(value) != 2:
            raise TypeError(f"{name} must be a number or a (min, max) pair, got {describe(value)}")
        pair = (as_number(value[0], name), as_number(value[1], name))
    if pair[0] > pair[1]:
        raise ValueError(f"{name} must satisfy min <= max, got {describe(value)}")
    if pair[0] < low or pair[1] > high:
        raise ValueError(f"{name} must lie in [{low}, {high}], got {describe(value)}")
    return pair


def check_choice(value: object, name: str, choices: Sequence[str]) -> str:
    """One of ``choices``."""
    if not isinstance(value, str) or value not in choices:
        raise ValueError(f"{name} must be one of {tuple(choices)}, got {value!r}")
    return value


def check_generator(generator: object, device: torch.device, name: str = "generator") -> None:
    """Raise unless ``generator`` is ``None`` or a ``torch.Generator`` on ``device``'s type."""
    if generator is None:
        return
    if not isinstance(generator, torch.Generator):
        raise TypeError(f"{name} must be a torch.Generator or None, got {type(generator).__name__}")
    if torch.device(generator.device).type != torch.device(device).type:
        raise ValueError(
            f"{name} lives on {generator.device} but the frames live on {device}; "
            "random kernels need a generator on the frames' device"
        )


def index_on(index: Tensor, device: torch.device) -> Tensor:
    """``index`` (a CPU tensor) on ``device``; no op when it is there already."""
    return index if device.type == "cpu" else index.to(device)
