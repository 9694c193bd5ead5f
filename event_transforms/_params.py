"""The one declaration of an operation's per-sample arguments, and its one check.

An operation's per-sample arguments are declared once, beside its dispatcher in
``functional/<topic>.py``, as a dict of :class:`Param` (kind, trailing shape, range),
or as a function of the batch shape where a range depends on T, H, W or
B (a window inside T, a box inside H×W, a partner in [0, B)). Both paths check against
that declaration with the same leaf check:

- the public dispatcher (``F.rotate(frames, angle)``) through :func:`check_args`, which
  first turns each argument (a number, a sequence, an array or a tensor) into a
  ``(B, *shape)`` CPU tensor;
- a module (``RandomRotation()(frames, params=tree)``) through
  :func:`event_transforms.transforms.check_tree`, whose ``params_spec`` returns the same
  declaration.

Errors name the operation (or the module), the argument and the value seen.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from numbers import Real
from typing import Optional

import numpy as np
import torch
from torch import Tensor

from ._validation import as_number, describe

__all__ = ["Param", "check_args", "SEED"]

_KINDS = {"bool": torch.bool, "int": torch.int64, "float": torch.float64}


@dataclass(frozen=True)
class Param:
    """One per-sample argument: ``(B, *shape)`` values of ``kind`` within ``low``..``high``.

    Args:
        kind: ``"bool"``, ``"int"`` (any integer dtype, stored int64) or ``"float"`` (any
            float dtype, stored float64; must be finite).
        shape: the trailing shape after the batch dimension.
        low, high: bounds (``None``: unbounded), closed unless ``low_open``/``high_open``.
        choices: the only values allowed (integers), if not every value in range is.
        optional: the entry may be absent.
        low_open, high_open: the bound itself is excluded (a zoom factor > 0).
        rule: a check of a relation between one sample's entries that a range cannot say
            (corners that make a convex quadrilateral): called with the ``(B, *shape)``
            float64/int64 CPU values, returns ``None`` or what the values must be.

    Shape:
        - a checked value: ``(B, *shape)``; a dispatcher also takes ``shape`` (one value for
          every sample) or a number where ``shape`` is ``()``.

    Example:
        >>> Param("float", low=0.0, high=1.0)
        Param(kind='float', shape=(), low=0.0, high=1.0, choices=None, optional=False, low_open=False, high_open=False, rule=None)
    """

    kind: str
    shape: tuple[int, ...] = ()
    low: float | None = None
    high: float | None = None
    choices: tuple[int, ...] | None = None
    optional: bool = False
    low_open: bool = False
    high_open: bool = False
    rule: Optional[Callable[[Tensor], Optional[str]]] = None

    def range_text(self) -> str:
        """``[low, high]`` with open ends in parentheses (``inf`` where unbounded)."""
        low = -math.inf if self.low is None else self.low
        high = math.inf if self.high is None else self.high
        return f"{'(' if self.low_open else '['}{low}, {high}{')' if self.high_open else ']'}"


#: A per-sample seed of a counter-based stream: an int64 in [0, 2**63).
SEED = Param("int", low=0, high=2**63 - 1)


def _values(tensor: Tensor) -> np.ndarray:
    return np.asarray(tensor.tolist(), dtype=np.float64 if tensor.is_floating_point() else np.int64)


def check_leaf(value: object, spec: Param, batch: int, owner: str, where: str, shown: str | None = None) -> Tensor:
    """Check one ``(B, *shape)`` tensor against ``spec``; return it in the kind's dtype.

    ``owner`` and ``where`` name the operation or module and the argument or key;
    ``shown`` describes the value as the caller gave it (default: the tensor).
    """
    if not isinstance(value, Tensor):
        raise TypeError(f"{owner}: {where} must be a tensor, got {type(value).__name__}")

    def seen() -> str:  # described only for a message (no host read of a value that passes)
        return describe(value) if shown is None else shown

    want = (batch, *spec.shape)
    if tuple(value.shape) != want:
        raise ValueError(f"{owner}: {where} must have shape {want} (one entry per sample), got {seen()}")
    dtype = _KINDS[spec.kind]
    if spec.kind == "bool":
        if value.dtype != torch.bool:
            raise TypeError(f"{owner}: {where} must be a bool tensor (a per-sample gate), got {seen()}")
        return value
    if value.dtype == torch.bool or value.is_complex():
        raise TypeError(f"{owner}: {where} must hold {spec.kind} numbers, got {seen()}")
    if spec.kind == "int" and value.is_floating_point():
        raise TypeError(f"{owner}: {where} must be an integer tensor, got {seen()}")
    if value.device.type == "cpu" and value.numel() and not torch.compiler.is_compiling():
        numbers = _values(value)
        if spec.kind == "float" and not np.isfinite(numbers).all():
            raise ValueError(f"{owner}: {where} must be finite, got {seen()}")
        low = -math.inf if spec.low is None else spec.low
        high = math.inf if spec.high is None else spec.high
        below = numbers <= low if spec.low_open else numbers < low
        above = numbers >= high if spec.high_open else numbers > high
        if (below | above).any():
            raise ValueError(f"{owner}: {where} must lie in {spec.range_text()}, got {seen()}")
        if spec.choices is not None and not np.isin(numbers, spec.choices).all():
            raise ValueError(f"{owner}: {where} must hold values in {list(spec.choices)}, got {seen()}")
        if spec.rule is not None:
            problem = spec.rule(value.to(dtype))
            if problem is not None:
                raise ValueError(f"{owner}: {where} must {problem}, got {seen()}")
    return value if value.dtype == dtype else value.to(dtype)


def _as_tensor(op: str, name: str, value: object, spec: Param, batch: int) -> Tensor:
    """A number, a sequence, an array or a tensor as a ``(B, *shape)`` CPU tensor (unchecked range)."""
    where = f"{op}: {name}"
    integer = spec.kind == "int"
    if spec.kind != "bool" and isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{where} must be a number or a ({batch},) tensor, got {value!r}")
    if isinstance(value, (Real, np.generic)) and not isinstance(value, np.bool_):
        if spec.shape:
            raise TypeError(f"{where} must be {spec.shape} or {(batch, *spec.shape)} values, got {value!r}")
        number = float(value) if spec.kind == "float" else as_number(value, where, integer=True) if integer else bool(value)
        return torch.full((batch,), number, dtype=_KINDS[spec.kind])
    if not isinstance(value, (Tensor, Sequence, np.ndarray)) or isinstance(value, (str, bytes)):
        raise TypeError(f"{where} must be a number or a ({batch}, ...) tensor, got {type(value).__name__}")
    try:
        out = torch.as_tensor(np.asarray(value) if isinstance(value, Sequence) else value)
    except (TypeError, ValueError, RuntimeError):
        raise TypeError(f"{where} must hold real numbers, got {value!r}") from None
    if spec.kind != "bool" and (out.dtype == torch.bool or out.is_complex()):
        raise TypeError(f"{where} must hold real numbers, got dtype {out.dtype}")
    out = out.detach().cpu()
    if tuple(out.shape) == spec.shape:
        out = out.expand(batch, *spec.shape)
    if tuple(out.shape) != (batch, *spec.shape):
        expected = f"be a scalar or have shape ({batch},) to match the batch" if not spec.shape else \
            f"have shape {spec.shape} or {(batch, *spec.shape)}"
        raise ValueError(f"{where} must {expected}, got {describe(value)}")
    if integer and out.is_floating_point():
        if out.numel() and not bool((out.isfinite() & (out == out.round())).all()):
            raise TypeError(f"{where} must hold integers, got {describe(value)}")
        out = out.to(torch.int64)
    return out


def check_args(op: str, spec: Mapping[str, Param], batch: int, **values: object) -> dict[str, Tensor]:
    """A public operation's per-sample arguments as ``(B, *shape)`` CPU tensors, checked against ``spec``.

    Each value may be a number (shared by every sample), a sequence, an array or a tensor,
    of shape ``shape`` (shared) or ``(B, *shape)`` (one per sample). The check is the one a
    module's params tree gets (:func:`event_transforms.transforms.check_tree`): the same
    declaration, the same leaf check.

    Args:
        op: the operation's name, for messages (``"rotate"``).
        spec: the operation's declaration: argument name -> :class:`Param`.
        batch: the batch size B.
        **values: the arguments, by the names ``spec`` uses.

    Returns:
        The arguments by name: float64 or int64 (bool for ``"bool"``) CPU tensors ``(B, *shape)``.

    Raises:
        TypeError: a value that is not real numbers, a bool, an integer argument that is
            not whole.
        ValueError: a shape that is neither ``shape`` nor ``(B, *shape)``, a value that is not
            finite, out of range, or breaks the declared rule.

    Shape:
        - values: a number, ``shape`` or ``(B, *shape)``.
        - output: ``(B, *shape)`` per argument.

    Example:
        >>> check_args("rotate", {"angle": Param("float")}, 2, angle=30)["angle"]
        tensor([30., 30.], dtype=torch.float64)
        >>> check_args("rotate", {"angle": Param("float")}, 1, angle=float("nan"))
        Traceback (most recent call last):
        ...
        ValueError: rotate: angle must be finite, got nan
    """
    out: dict[str, Tensor] = {}
    for name, value in values.items():
        param = spec[name]
        shown = describe(value)
        out[name] = check_leaf(_as_tensor(op, name, value, param, batch), param, batch, op, name, shown)
    return out
