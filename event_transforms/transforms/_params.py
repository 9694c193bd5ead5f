"""What a module's parameters are, and the one check of a user-given parameters tree.

Every module describes the entries of its params dict with :meth:`EventTransform.params_spec`
(key -> :class:`Param`: kind, trailing shape, closed range); containers describe their
children as ``(child, shape)`` pairs. ``module(frames, params=tree)`` checks ``tree``
against that description once, at the entry (:func:`check_tree`), recursively through the
containers, and raises a ``ValueError``/``TypeError`` naming the module, the key and the
value; kernels behind it trust the tree.

The checks read the values on the host. Trees from ``make_params`` are CPU tensors, so
this waits for nothing; values of a tree the caller moved to an accelerator (e.g. for
CUDA-graph capture), or of a call traced by ``torch.compile``, are not read: their keys,
dtypes and shapes are checked, their ranges are not. The reads run inside the profiler range :data:`CHECK_RANGE`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Union

import numpy as np
import torch
from torch import Tensor

from .._validation import describe

if TYPE_CHECKING:  # pragma: no cover
    from .base import EventTransform

__all__ = ["Param", "Params", "Spec", "check_tree", "slice_params", "CHECK_RANGE"]

#: A call's parameters: a dict whose leaves are ``(B, ...)`` tensors and whose inner nodes
#: are the parameters of a container's children.
Params = dict[str, Any]

#: Profiler range around the host-side reads of a user-given tree (CPU parameters: no
#: device work; ``benchmarks._common.count_ops`` leaves them out of a call's launches).
CHECK_RANGE = "event_transforms::check_params"

_KINDS = {"bool": torch.bool, "int": torch.int64, "float": torch.float64}


@dataclass(frozen=True)
class Param:
    """One entry of a params dict: ``(B, *shape)`` values of ``kind`` within ``[low, high]``.

    Args:
        kind: ``"bool"``, ``"int"`` (any integer dtype, stored int64) or ``"float"`` (any
            float dtype, stored float64; must be finite).
        shape: the trailing shape after the batch dimension.
        low, high: closed bounds (``None``: unbounded).
        choices: the only values allowed (integers), if not every value in range is.
        optional: the entry may be absent.

    Example:
        >>> Param("float", low=0.0, high=1.0)
        Param(kind='float', shape=(), low=0.0, high=1.0, choices=None, optional=False)
    """

    kind: str
    shape: tuple[int, ...] = ()
    low: float | None = None
    high: float | None = None
    choices: tuple[int, ...] | None = None
    optional: bool = False


#: A module's description of its params dict: a :class:`Param` per own entry and a
#: ``(child, shape)`` pair per child of a container.
Spec = Mapping[str, Union[Param, "tuple[EventTransform, torch.Size]"]]


def _values(tensor: Tensor) -> np.ndarray:
    return np.asarray(tensor.tolist(), dtype=np.float64 if tensor.is_floating_point() else np.int64)


def _check_leaf(value: object, spec: Param, batch: int, owner: str, where: str) -> Tensor:
    if not isinstance(value, Tensor):
        raise TypeError(f"{owner}: {where} must be a tensor, got {type(value).__name__}")
    want = (batch, *spec.shape)
    if tuple(value.shape) != want:
        raise ValueError(f"{owner}: {where} must have shape {want} (one entry per sample), got {describe(value)}")
    dtype = _KINDS[spec.kind]
    if spec.kind == "bool":
        if value.dtype != torch.bool:
            raise TypeError(f"{owner}: {where} must be a bool tensor (a per-sample gate), got {describe(value)}")
        return value
    if value.dtype == torch.bool or value.is_complex():
        raise TypeError(f"{owner}: {where} must hold {spec.kind} numbers, got {describe(value)}")
    if spec.kind == "int" and value.is_floating_point():
        raise TypeError(f"{owner}: {where} must be an integer tensor, got {describe(value)}")
    if value.device.type == "cpu" and value.numel() and not torch.compiler.is_compiling():
        numbers = _values(value)
        if spec.kind == "float" and not np.isfinite(numbers).all():
            raise ValueError(f"{owner}: {where} must be finite, got {describe(value)}")
        low = -math.inf if spec.low is None else spec.low
        high = math.inf if spec.high is None else spec.high
        if ((numbers < low) | (numbers > high)).any():
            raise ValueError(f"{owner}: {where} must lie in [{low}, {high}], got {describe(value)}")
        if spec.choices is not None and not np.isin(numbers, spec.choices).all():
            raise ValueError(f"{owner}: {where} must hold values in {list(spec.choices)}, got {describe(value)}")
    return value if value.dtype == dtype else value.to(dtype)


def check_tree(module: EventTransform, params: object, shape: torch.Size, path: str = "params") -> dict[str, Any]:
    """Check ``params`` against ``module.params_spec(shape)``; return it with canonical dtypes.

    Raises:
        TypeError: not a dict, a leaf that is not a tensor or has the wrong kind.
        ValueError: a missing or unknown key, a wrong shape, a value out of range or not finite.
    """
    owner = type(module).__name__
    if not isinstance(params, Mapping):
        raise TypeError(f"{owner}: {path} must be a dict returned by make_params, got {type(params).__name__}")
    batch = shape[0]
    spec = module.params_spec(shape)
    checked = _CheckedParams()
    checked.owner = owner
    if spec is None:
        raise TypeError(f"{owner}.params_spec returned None; every module declares its params (a dict of Param)")
    spec = dict(spec)
    if "apply" not in spec:
        spec["apply"] = Param("bool", optional=module.p >= 1)
    unknown = sorted(set(params) - set(spec), key=str)
    if unknown:
        raise ValueError(
            f"{owner}: {path} has unknown key(s) {unknown}; {owner} takes {sorted(spec)} (pass the dict that make_params returns)"
        )
    for key, entry in spec.items():
        where = f"{path}[{key!r}]"
        if key not in params:
            if isinstance(entry, Param) and entry.optional:
                continue
            raise ValueError(f"{owner}: {path} has no entry {key!r} (it has {sorted(params)}); pass the dict that make_params returns")
        if isinstance(entry, Param):
            checked[key] = _check_leaf(params[key], entry, batch, owner, where)
        else:
            child, child_shape = entry
            checked[key] = check_tree(child, params[key], child_shape, where)
    return checked


class _CheckedParams(dict):
    """A params dict that names the module and the key when a key is missing."""

    owner = "transform"

    def __missing__(self, key: str) -> Any:
        raise ValueError(
            f"params of {self.owner} has no entry {key!r} (it has {sorted(self)}); pass the "
            "dict that make_params returns"
        )


def slice_params(params: Params, index: Tensor) -> Params:
    """The parameters of the samples ``index`` (a CPU int64 tensor): every leaf indexed on dim 0."""
    out = type(params)()
    if isinstance(params, _CheckedParams) and isinstance(out, _CheckedParams):
        out.owner = params.owner
    for key, value in params.items():
        out[key] = slice_params(dict(value), index) if isinstance(value, Mapping) and not isinstance(value, dict) else (
            slice_params(value, index) if isinstance(value, dict) else value.index_select(0, index))
    return out
