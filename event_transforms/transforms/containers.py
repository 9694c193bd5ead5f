"""Containers: ``Compose`` (hybrid), ``OneOf`` (independent) and ``RandomApply``.

Containers only chain. Their :meth:`~EventTransform.make_params` returns one entry per
child (``"0"``, ``"1"``, ...; each child's own tree, drawn for the whole batch with the
batch's metadata), plus the container's own draws (``"index"`` for :class:`OneOf`,
``"apply"`` for :class:`RandomApply`), so a whole pipeline's draw can be logged and
replayed. ``OneOf`` and ``RandomApply`` gather the samples that take each branch, slice
the branch's parameters to them, and run the branch once on that sub-batch (no per-sample
loop), so an unused branch costs nothing. Members that are not event transforms (plain
functions, torchvision transforms) are wrapped by :func:`as_transform` and called as
``function(frames)``.

**Coupled members** (:attr:`~event_transforms.EventTransform.couples_samples`: CutMix,
MixUp). ``Compose`` runs every member on the whole batch, so it takes them: it declares
the coupling itself and mixes the labels (the second input, or the dict entry named by the
members' ``label_key``) through its members' :meth:`~EventTransform.apply_labels`, in
order. ``OneOf`` and ``RandomApply`` hand a member only the samples that drew it, so a
partner index would point outside the sub-batch: they refuse a coupled member at
construction with a ``TypeError`` naming it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Callable

import torch
from torch import Tensor, nn

from .._validation import as_number, check_probability
from ..events.batch import EventBatch
from .base import EventTransform, Param, Params, _draw_device, _events_by_group, apply_by_group, as_transform, slice_params

__all__ = ["Compose", "OneOf", "RandomApply"]

Metadata = Mapping[str, Any] | Sequence[Mapping[str, Any]] | None


def _refuse_coupled(member: EventTransform, where: str, container: str) -> None:
    if member.couples_samples:
        raise TypeError(
            f"{where} ({type(member).__name__}) mixes samples of the batch (couples_samples), but {container} hands "
            "its members sub-batches, where partners and labels would not match; put it in a Compose (whole batch), "
            "e.g. Compose([OneOf([...]), CutMix(p=0.5)]), or give it its own p="
        )


def _members(transforms: object, name: str, *, events_first: bool = False, videos: bool = False) -> Any:
    """The members as an ``nn.ModuleList`` of :class:`EventTransform` (typed ``Any``: a
    ``ModuleList`` yields ``nn.Module`` to type checkers)."""
    if isinstance(transforms, (nn.Module, str, bytes)) or not isinstance(transforms, Sequence):
        raise TypeError(
            f"{name} must be a sequence of transforms or callables, got {type(transforms).__name__}"
        )
    members = nn.ModuleList(as_transform(t, f"{name}[{i}]") for i, t in enumerate(transforms))
    for i, member in enumerate(members):
        if member.takes_video and not (videos or (events_first and i == 0)):
            raise TypeError(
                f"{name}[{i}] ({type(member).__name__}) turns a video into events and can stand only first in a "
                "Compose, or in a OneOf whose every member takes a video"
            )
        if member.takes_events and not events_first:
            raise TypeError(
                f"{name}[{i}] ({type(member).__name__}) turns events into frames and can stand only in a "
                "Compose (first for raw streams, anywhere for an EventBatch)"
            )
    return members


class Compose(EventTransform):
    """Apply transforms one after another to every sample: the paper's *hybrid* combination.

    The first member may be :class:`~event_transforms.EventsToFrames`: the pipeline then
    takes an event stream (a tonic-style dataset transform) and the rest sees its frames.

    Args:
        transforms: event transforms or callables ``frames -> frames``; an
            ``EventsToFrames`` only first.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)`` frames, or an :class:`~event_transforms.EventBatch`
        when every member takes one; the output is what the members make of it (frames from an
        event stream when the first member is ``EventsToFrames``).

    Example:
        >>> from event_transforms import FrameShift, HorizontalFlip, RandomRotation
        >>> hybrid = Compose([FrameShift(-1), HorizontalFlip()])
        >>> hybrid(torch.arange(8.).reshape(2, 2, 1, 2))[:, :, 0].tolist()
        [[[5.0, 4.0], [7.0, 6.0]], [[0.0, 0.0], [0.0, 0.0]]]
        >>> params = Compose([FrameShift(-1), RandomRotation(10.0)]).make_params(
        ...     (2, 36, 2, 70, 75), generator=torch.Generator().manual_seed(0))
        >>> params["0"]["shift"].tolist(), params["1"]["angle"].shape
        ([-1, -1], torch.Size([2]))
    """

    def __init__(self, transforms: Sequence[EventTransform | Callable[[Tensor], Tensor]]) -> None:
        super().__init__()
        self.transforms: Sequence[EventTransform] = _members(transforms, "transforms", events_first=True)
        keys = {t.label_key for t in self.transforms if t.couples_samples and t.label_key is not None}
        if len(keys) > 1:
            raise ValueError(f"transforms: coupled members must agree on label_key, got {sorted(keys)}")
        self._label_key = keys.pop() if keys else None

    @property
    def couples_samples(self) -> bool:  # type: ignore[override]  # read-only here: follows the members
        """Whether a member mixes samples: then the labels are mixed by the members, in order."""
        return any(t.couples_samples for t in self.transforms)

    @property
    def label_key(self) -> str | None:  # type: ignore[override]  # read-only here: follows the members
        """The coupled members' ``label_key`` (for dict inputs)."""
        return self._label_key

    def apply_labels(self, labels: Tensor, params: Params) -> Tensor:
        for i, transform in enumerate(self.transforms):
            if transform.couples_samples:
                labels = transform._run_labels(labels, params[str(i)])
        return labels

    def params_spec(self, shape: torch.Size) -> dict[str, Any]:
        spec: dict[str, Any] = {}
        for i, transform in enumerate(self.transforms):
            spec[str(i)] = (transform, shape)
            shape = transform.output_shape(shape)
        return spec

    @property
    def takes_events(self) -> bool:
        return len(self.transforms) > 0 and self.transforms[0].takes_events

    @property
    def takes_video(self) -> bool:
        return len(self.transforms) > 0 and self.transforms[0].takes_video

    def video_shape(self, shape: Sequence[int]) -> torch.Size:
        return self.transforms[0].video_shape(shape)

    def events_to_frames(self, events: Any) -> Tensor:
        return self.transforms[0].events_to_frames(events)

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Metadata = None) -> Params:
        params: Params = {}
        for i, transform in enumerate(self.transforms):
            params[str(i)] = transform.make_params(shape, generator=generator, metadata=metadata)
            shape = transform.output_shape(shape)
        return params

    def output_shape(self, shape: torch.Size) -> torch.Size:
        for transform in self.transforms:
            shape = transform.output_shape(shape)
        return shape

    def apply_transform(self, frames: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        for i, transform in enumerate(self.transforms):
            shape = transform.output_shape(frames.shape) if isinstance(frames, Tensor) else None  # not for events
            frames = transform._run(frames, params[str(i)])
            if shape is not None and isinstance(frames, Tensor) and frames.shape != shape:
                raise ValueError(
                    f"transforms[{i}] ({type(transform).__name__}) returned shape {tuple(frames.shape)}, "
                    f"expected {tuple(shape)}"
                )
        return frames



class OneOf(EventTransform):
    """Give each sample exactly one of the transforms: the paper's *independent* combination.

    Each sample draws its branch (uniformly, or by ``weights``) into ``params["index"]``;
    each branch runs once on the sub-batch that drew it. The output dtype is the promotion
    of every branch's dtype, whatever the draw. Every branch must keep the batch shape.

    Args:
        transforms: event transforms or callables, at least one.
        weights: non-negative relative probabilities, one per transform (default equal).

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)`` frames, or an :class:`~event_transforms.EventBatch`
        when every member takes one; the output is what the members make of it (the batch shape kept).

    Example:
        >>> from event_transforms import FrameShift, Resize
        >>> independent = OneOf([Resize(1.25), FrameShift(-1)])
        >>> params = independent.make_params((6, 36, 2, 70, 75), generator=torch.Generator().manual_seed(0))
        >>> params["index"].tolist(), params["1"]["shift"].tolist()
        ([1, 1, 0, 1, 1, 1], [-1, -1, -1, -1, -1, -1])
    """

    weights: Tensor  # a buffer

    def __init__(
        self,
        transforms: Sequence[EventTransform | Callable[[Tensor], Tensor]],
        weights: Sequence[float] | None = None,
    ) -> None:
        super().__init__()
        self.transforms: Sequence[EventTransform] = _members(transforms, "transforms", videos=True)
        videos = [m.takes_video for m in self.transforms]
        if any(videos) and not all(videos):
            raise TypeError(
                f"transforms: every member of a OneOf takes the same input; members {[i for i, v in enumerate(videos) if v]} "
                f"turn a video into events and members {[i for i, v in enumerate(videos) if not v]} do not"
            )
        self._takes_video = bool(videos) and all(videos)
        for i, member in enumerate(self.transforms):
            _refuse_coupled(member, f"transforms[{i}]", "OneOf")
        n = len(self.transforms)
        if n == 0:
            raise ValueError("transforms must hold at least one transform, got an empty sequence")
        if weights is None:
            weights = [1.0] * n
        if isinstance(weights, (str, bytes)) or not isinstance(weights, Sequence) or len(weights) != n:
            raise ValueError(f"weights must have one entry per transform ({n}), got {weights!r}")
        values = [as_number(w, "weights", low=0.0) for w in weights]
        if sum(values) <= 0:
            raise ValueError(f"weights must not all be zero, got {weights!r}")
        total = sum(values)
        self.register_buffer("weights", torch.tensor([v / total for v in values], dtype=torch.float64), persistent=False)

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Metadata = None) -> Params:
        batch = shape[0]
        if batch:
            index = torch.multinomial(
                self.weights.to(_draw_device(generator)), batch, replacement=True, generator=generator
            ).cpu()
        else:
            index = torch.zeros(0, dtype=torch.int64)
        params: Params = {"index": index}
        for i, transform in enumerate(self.transforms):
            params[str(i)] = transform.make_params(shape, generator=generator, metadata=metadata)
        return params

    def params_spec(self, shape: torch.Size) -> dict[str, Any]:
        spec: dict[str, Any] = {"index": Param("int", low=0, high=len(self.transforms) - 1)}
        spec.update({str(i): (t, shape) for i, t in enumerate(self.transforms)})
        return spec

    @property
    def takes_video(self) -> bool:
        return self._takes_video

    def video_shape(self, shape: Sequence[int]) -> torch.Size:
        shapes = {tuple(t.video_shape(shape)) for t in self.transforms}
        if len(shapes) > 1:
            raise ValueError(f"transforms: the members read a video of shape {tuple(shape)} differently: {sorted(shapes)}")
        return torch.Size(shapes.pop())

    def apply_transform(self, frames: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        branches = [
            (lambda sub, index, t=t, i=i: t._run(sub, slice_params(params[str(i)], index)))
            for i, t in enumerate(self.transforms)
        ]
        if self._takes_video and isinstance(frames, Tensor):
            return _events_by_group(frames, params["index"], branches)
        return apply_by_group(frames, params["index"], branches)


    def _settings(self) -> str:
        return f"weights={[round(w, 4) for w in self.weights.tolist()]}"


class RandomApply(EventTransform):
    """Apply ``transform`` to each sample with probability ``p``; other samples pass unchanged.

    The same as giving the transform ``p=``; kept for transforms that have no ``p`` (plain
    callables, torchvision transforms) and for torchvision's spelling.

    Args:
        transform: an event transform or a callable.
        p: probability per sample, in [0, 1].

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)`` frames, or an :class:`~event_transforms.EventBatch`
        when every member takes one; the output is what the members make of it (the batch shape kept).

    Example:
        >>> from event_transforms import FrameShift
        >>> gate = RandomApply(FrameShift(1), p=0.5)
        >>> params = gate.make_params((4, 3, 2, 5, 5), generator=torch.Generator().manual_seed(0))
        >>> params["apply"].tolist(), params["0"]["shift"].tolist()
        ([False, False, True, False], [1, 1, 1, 1])
    """

    def __init__(self, transform: EventTransform | Callable[[Tensor], Tensor], p: float = 0.5) -> None:
        super().__init__(p=check_probability(p, "p"))
        self.transform = as_transform(transform)
        if self.transform.takes_video:
            raise TypeError(
                f"transform ({type(self.transform).__name__}) turns a video into events, so RandomApply would give "
                "events for some samples and the video for others; put it first in a Compose, or give a OneOf the "
                "cameras to choose from"
            )
        if self.transform.takes_events:
            raise TypeError(
                f"transform ({type(self.transform).__name__}) turns events into frames and can stand only "
                "first in a Compose; here it would be handed frames"
            )
        _refuse_coupled(self.transform, "transform", "RandomApply")

    def params_spec(self, shape: torch.Size) -> dict[str, Any]:
        return {"0": (self.transform, shape)}

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Metadata = None) -> Params:
        return {"0": self.transform.make_params(shape, generator=generator, metadata=metadata)}

    def apply_transform(self, frames: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        return self.transform._run(frames, params["0"])

