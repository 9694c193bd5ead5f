"""Writing your own transform: the names an author needs, apart from the transforms a user applies
(as torchvision keeps ``Transform`` apart from its transforms).

- :class:`EventTransform`: the base class (``sample_params``, ``params_spec``,
  ``apply_transform``); ``p=`` gating, replay from a params tree, containers, dict and
  ``tv_tensors.Video`` inputs come with it.
- :class:`Param` and :data:`Params`: one per-sample argument's declaration (kind, trailing
  shape, range, choices) and a params tree (a dict of ``(B, ...)`` CPU tensors, nested for
  containers).
- :func:`check_args`: an operation's per-sample arguments checked against its declaration,
  the check a params tree gets.
- :func:`slice_params`: the parameters of some samples of a tree, to replay them alone
  (``module(x[i:i+1], params=slice_params(tree, [i]))`` equals ``module(x, params=tree)[i]``).
- :func:`as_transform`: a transform, or a :class:`~event_transforms.Lambda` around a callable.

``docs/write_your_own.md`` walks through a whole new transform. These names are also importable
from :mod:`event_transforms.transforms` and, for compatibility, from the top level; they are not in
``event_transforms.__all__`` or ``event_transforms.transforms.__all__``, which list the transforms.

Example:
    >>> import torch
    >>> from event_transforms.authoring import EventTransform, Param, slice_params
    >>> class Scale(EventTransform):
    ...     def sample_params(self, shape, *, generator=None, metadata=None):
    ...         return {"factor": 1 + torch.rand(shape[0], generator=generator, dtype=torch.float64)}
    ...     def params_spec(self, shape):
    ...         return {"factor": Param("float", low=1.0, high=2.0)}
    ...     def apply_transform(self, frames, params):
    ...         return frames * params["factor"].to(frames.dtype).view(-1, 1, 1, 1, 1)
    >>> frames = torch.ones(3, 2, 2, 4, 4)
    >>> module = Scale()
    >>> tree = module.make_params(frames.shape, generator=torch.Generator().manual_seed(0))
    >>> torch.equal(module(frames[1:2], params=slice_params(tree, [1])), module(frames, params=tree)[1:2])
    True
"""

from __future__ import annotations

from ._params import check_args
from .transforms._tree import slice_params
from .transforms.base import EventTransform, Param, Params, as_transform

__all__ = ["EventTransform", "Param", "Params", "as_transform", "check_args", "slice_params"]
