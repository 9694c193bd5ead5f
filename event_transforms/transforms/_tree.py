"""What a module's parameters are, and the one check of a user-given parameters tree.

Every module describes the entries of its params dict with :meth:`EventTransform.params_spec`
(key -> :class:`Param`: kind, trailing shape, range); an operation's declaration lives once,
beside its dispatcher in ``functional/<topic>.py``, and the module returns it, so
``F.rotate(x, angle)`` (:func:`event_transforms._params.check_args`) and
``RandomRotation()(x, params=tree)`` are checked by the same objects. Containers describe their
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

from collections.abc import Mapping, Sequence
from typing import Any, Protocol, Union

import torch
from torch import Tensor

from .._params import Param, check_leaf


__all__ = ["Param", "Params", "Spec", "check_tree", "slice_params", "CHECK_RANGE"]

#: A call's parameters: a dict whose leaves are ``(B, ...)`` tensors and whose inner nodes
#: are the parameters of a container's children.
Params = dict[str, Any]

#: Profiler range around the host-side reads of a user-given tree (CPU parameters: no
#: device work; ``event_transforms._profiling.count_ops`` leaves them out of a call's launches).
CHECK_RANGE = "event_transforms::check_params"

#: A module's description of its params dict: a :class:`Param` per own entry and a
#: ``(child, shape)`` pair per child of a container.
Spec = Mapping[str, Union[Param, "tuple[Declares, torch.Size]"]]


class Declares(Protocol):
    """What :func:`check_tree` reads of a module: its gate probability and its declaration
    (:class:`~event_transforms.EventTransform` is one; a Protocol, so this module needs no
    import of the base class)."""

    p: float

    def params_spec(self, shape: torch.Size) -> Spec: ...


def check_tree(module: Declares, params: object, shape: torch.Size, path: str = "params") -> dict[str, Any]:
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
            checked[key] = check_leaf(params[key], entry, batch, owner, where)
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


def slice_params(params: Params, index: Tensor | Sequence[int]) -> Params:
    """The parameters of the samples ``index`` of a params tree: every leaf indexed on dim 0.

    Public as :func:`event_transforms.authoring.slice_params`: a sample's output is a function
    of its own input and its own slice of the tree, so ``module(x[i:i+1], params=slice_params(tree,
    [i]))`` equals ``module(x, params=tree)[i:i+1]`` (a logged sample replays alone).

    Args:
        params: a tree from ``module.make_params`` (nested dicts of ``(B, ...)`` CPU tensors).
        index: the samples to keep: a sequence of ints or a CPU int64 tensor.

    Shape:
        - params: leaves ``(B, ...)``.
        - output: leaves ``(len(index), ...)``.

    Returns:
        The same tree, each leaf indexed on its first dimension.

    Example:
        >>> import event_transforms as et
        >>> tree = et.RandomRotation(30.0).make_params((4, 6, 2, 8, 8), generator=torch.Generator().manual_seed(0))
        >>> tree["angle"].shape, slice_params(tree, [2])["angle"].shape
        (torch.Size([4]), torch.Size([1]))
    """
    if not isinstance(index, Tensor):
        index = torch.as_tensor(list(index), dtype=torch.int64)
    out = type(params)()
    if isinstance(params, _CheckedParams) and isinstance(out, _CheckedParams):
        out.owner = params.owner
    for key, value in params.items():
        out[key] = slice_params(dict(value), index) if isinstance(value, Mapping) and not isinstance(value, dict) else (
            slice_params(value, index) if isinstance(value, dict) else value.index_select(0, index))
    return out
