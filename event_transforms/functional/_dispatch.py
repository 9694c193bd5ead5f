"""The one registry of kernels: operation x input type -> kernel (torchvision v2's pattern).

Every operation has a public *dispatcher* in its topic file (``rotate`` in ``affine.py``,
``frame_shift`` in ``temporal.py``, ``drop_random`` in ``drop.py``, ...) and one *kernel*
per input type beside it, named by one rule: ``<op>_frames`` for a ``(B, T, 2, H, W)``
tensor, ``<op>_events`` for an :class:`~event_transforms.EventBatch`. Both are registered
here under the dispatcher with :func:`register_kernel`:

- a dispatcher (``F.rotate(x, angle)``) checks its arguments, brings frames to a batch,
  and calls :func:`call_kernel`;
- a module's ``apply_transform`` calls :func:`call_kernel` with the dispatcher and its params tree,
  already checked against its ``params_spec`` (kernels trust their arguments).

An input type with no kernel is refused by name (``TypeError``), so an operation without an
event kernel tells the caller to bin first.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

from torch import Tensor

from .._validation import as_batch, check_frames
from ..events.batch import EventBatch

__all__ = ["register_kernel", "kernel_for", "call_kernel", "has_kernel", "NoKernelError"]

Kernel = TypeVar("Kernel", bound=Callable[..., Any])

#: dispatcher -> {input type -> kernel}
_KERNELS: dict[Callable[..., Any], dict[type, Callable[..., Any]]] = {}

_KIND = {Tensor: "frames", EventBatch: "an EventBatch"}


class NoKernelError(TypeError):
    """An operation has no kernel for the input's type (a ``TypeError``; modules re-raise it
    with their own name). ``events`` is true when the input was an EventBatch."""

    def __init__(self, message: str, *, events: bool, detail: str) -> None:
        super().__init__(message)
        self.events = events
        self.detail = detail


def register_kernel(dispatcher: Callable[..., Any], input_type: type) -> Callable[[Kernel], Kernel]:
    """Decorator: the function is ``dispatcher``'s kernel for inputs of ``input_type``.

    Args:
        dispatcher: the public operation (e.g. :func:`~event_transforms.functional.rotate`).
        input_type: ``torch.Tensor`` (frames) or :class:`~event_transforms.EventBatch`.

    Example:
        >>> import torch
        >>> from event_transforms import functional as F
        >>> kernel_for(F.rotate, torch.zeros(1, 1, 2, 3, 3)) is F.rotate_frames
        True
    """
    if input_type not in _KIND:
        raise TypeError(f"input_type must be torch.Tensor or EventBatch, got {input_type!r}")

    def register(kernel: Kernel) -> Kernel:
        _KERNELS.setdefault(dispatcher, {})[input_type] = kernel
        return kernel

    return register


def has_kernel(dispatcher: Callable[..., Any], input_type: type) -> bool:
    """Whether ``dispatcher`` has a kernel for ``input_type`` (``torch.Tensor`` or ``EventBatch``).

    Args:
        dispatcher: the public operation.
        input_type: ``torch.Tensor`` or :class:`~event_transforms.EventBatch`.

    Example:
        >>> import torch
        >>> from event_transforms import EventBatch, functional as F
        >>> has_kernel(F.rotate, EventBatch), has_kernel(F.spatial_jitter, torch.Tensor)
        (True, False)
    """
    return input_type in _KERNELS.get(dispatcher, {})


def kernel_for(dispatcher: Callable[..., Any], inputs: object) -> Callable[..., Any]:
    """The kernel of ``dispatcher`` for the type of ``inputs``.

    Args:
        dispatcher: the public operation.
        inputs: frames (a tensor) or an :class:`~event_transforms.EventBatch`.

    Shape:
        - inputs: frames ``(B, T, 2, H, W)`` or an EventBatch; only the type is read.

    Example:
        >>> import torch
        >>> from event_transforms import functional as F
        >>> kernel_for(F.horizontal_flip, torch.zeros(1, 1, 2, 2, 2)).__name__
        'horizontal_flip_frames'

    Raises:
        TypeError: ``inputs`` is neither frames nor an EventBatch, or the operation has no
            kernel for its type (the message says how to bin events first).
    """
    kernels = _KERNELS.get(dispatcher, {})
    name = getattr(dispatcher, "__name__", repr(dispatcher))
    for input_type in (EventBatch, Tensor):
        if isinstance(inputs, input_type):
            kernel = kernels.get(input_type)
            if kernel is not None:
                return kernel
            if input_type is EventBatch:
                detail = "has no kernel for an EventBatch; bin the events first with EventsToFrames " \
                    "(it can stand anywhere in a Compose)"
                raise NoKernelError(f"{name} {detail}", events=True, detail=detail)
            assert isinstance(inputs, Tensor)
            detail = "works on events only: pass an EventBatch (EventBatch.from_streams or collate_events), " \
                f"got frames of shape {tuple(inputs.shape)}"
            raise NoKernelError(f"{name} {detail}", events=False, detail=detail)
    check_frames(inputs)  # not a tensor: raises the standard message
    raise TypeError(f"{name} takes frames or an EventBatch, got {type(inputs).__name__}")  # pragma: no cover


def call_kernel(dispatcher: Callable[..., Any], inputs: Any, *args: Any, **kwargs: Any) -> Any:
    """``kernel_for(dispatcher, inputs)(inputs, *args, **kwargs)``: what a module's ``apply_transform`` calls.

    The kernel gets its arguments as they are (already checked, per sample): the dispatcher's
    argument checks are skipped.

    Args:
        dispatcher: the public operation.
        inputs: frames ``(B, T, 2, H, W)`` or an EventBatch.
        *args, **kwargs: the kernel's arguments.

    Shape:
        - inputs: frames ``(B, T, 2, H, W)`` or an EventBatch.
        - output: what the kernel returns (frames or an EventBatch).

    Example:
        >>> import torch
        >>> from event_transforms import functional as F
        >>> frames = torch.arange(4.0).view(1, 1, 2, 1, 2)
        >>> call_kernel(F.horizontal_flip, frames, torch.tensor([True])).flatten().tolist()
        [1.0, 0.0, 3.0, 2.0]
    """
    return kernel_for(dispatcher, inputs)(inputs, *args, **kwargs)


def batch_of(inputs: object, name: str = "frames") -> tuple[Any, int, Callable[[Any], Any]]:
    """A dispatcher's entry: ``(batch, B, restore)``.

    Frames are checked and brought to ``(B, T, 2, H, W)`` (``restore`` removes the batch
    dimension again for a single sequence); an EventBatch is returned as it is.
    """
    if isinstance(inputs, EventBatch):
        return inputs, len(inputs), _same
    batch, unbatch = as_batch(check_frames(inputs, name))
    return batch, batch.shape[0], unbatch


def shape_of(batch: Any) -> tuple[int, ...]:
    """The ``(B, T, 2, H, W)`` a batch of frames or an EventBatch draws parameters for."""
    return tuple(batch.frame_shape if isinstance(batch, EventBatch) else batch.shape)


def _same(value: Any) -> Any:
    return value
