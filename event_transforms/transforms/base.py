"""The base class of every transform module, its calling convention and parameter trees.

A module holds settings. A call has two steps:

1. :meth:`EventTransform.make_params` sees the whole batch shape ``(B, T, 2, H, W)`` (and
   the batch's metadata) and draws *every* random number the call will use, as a dict of
   ``(B, ...)`` CPU tensors (so CPU and CUDA calls draw the same numbers). Kernels that
   need randomness of their own (temporal event shifting, event drop, Poisson noise) get
   per-sample seeds from it and draw from counter-based streams keyed by each sample's
   seed (:mod:`event_transforms.functional._random`), so a sample's output is a function
   of its own input and its own slice of the tree (per-sample purity): ``module(x[i:i+1],
   params=slice_params(tree, [i]))`` equals ``module(x, params=tree)[i]``. Containers return one entry per child, so a call's
   parameters are one tree.
2. :meth:`EventTransform.apply_transform` hands a batch (frames or an :class:`EventBatch`) and its
   parameters to the operation's kernel for that input type, through the registry of
   :mod:`event_transforms.functional` (``call_kernel(F.rotate, inputs, ...)``).

``module(frames, params=tree)`` replays a draw exactly, whatever the global RNG state.
Subclasses override :meth:`~EventTransform.sample_params` and :meth:`~EventTransform.apply_transform`;
``forward`` and ``make_params`` are not overridden.

The calling convention (owned here and nowhere else): every module is called as
``module(*inputs, generator=None, params=None, metadata=None)``. The frames are the first
input (an event stream instead for a module whose :attr:`~EventTransform.takes_events` is
true: :class:`~event_transforms.EventsToFrames`, or a ``Compose`` starting with one): a tensor, a ``torchvision.tv_tensors.Video`` (returned as a ``Video``) or a dict
holding them under ``"frames"``. Any further inputs (labels, ...) and the dict's other
entries pass through unchanged, as in torchvision's v2 transforms. Anything else a
container or data set is handed (a plain function, a torchvision transform) is wrapped by
:func:`as_transform` into a :class:`Lambda` called as ``function(frames)``.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping, Sequence
from typing import Any, cast, overload

import numpy as np
import torch
from torch import Tensor, nn

from .._validation import FRAME_DTYPES, as_batch, check_frames, check_probability, check_shape, index_on
from ..events.batch import EventBatch, merge_streams, replace_streams
from ..functional._dispatch import NoKernelError
from ..functional._random import draw_seeds
from ._tree import CHECK_RANGE, Param, Params, Spec, check_tree, slice_params

__all__ = ["EventTransform", "Params", "Param", "Lambda", "as_transform", "FRAMES_KEY"]

#: The key under which a dict input holds the frames.
FRAMES_KEY = "frames"

def _numpy_frames(frames: object) -> Any:
    """A numpy array of frames (tonic's ``ToFrame``, ``DiskCachedDataset``) as a tensor, converted
    once at the outermost transform; the memory is shared when torch can (the transforms never
    write into their input) and copied otherwise (read-only or negative-stride arrays)."""
    if not isinstance(frames, np.ndarray):
        return frames
    if frames.dtype.kind not in "biuf" or frames.dtype == np.uint16 or frames.dtype == np.uint32:
        raise TypeError(
            f"frames as a numpy array must have one of the frame dtypes {FRAME_DTYPES}, got numpy dtype {frames.dtype}"
        )
    if not frames.flags.writeable or any(stride < 0 for stride in frames.strides):
        frames = frames.copy()
    return torch.from_numpy(frames)


def _passthrough(frames: Any) -> Any:
    """What ``torch.from_numpy``/``torch.as_tensor`` become in a container: numpy frames were
    converted at its boundary already."""
    return _numpy_frames(frames)


def _video_of(frames: object) -> Any:
    """The ``tv_tensors.Video`` class if ``frames`` is one (torchvision is never imported here)."""
    module = sys.modules.get("torchvision.tv_tensors")
    if module is not None and isinstance(frames, module.Video):
        return module
    return None


# --------------------------------------------------------------------------- sampling


def _draw_device(generator: torch.Generator | None) -> torch.device:
    return torch.device("cpu") if generator is None else torch.device(generator.device)


def uniform(low: float, high: float, batch: int, generator: torch.Generator | None) -> Tensor:
    """``batch`` draws from U[low, high) as a float64 CPU tensor."""
    u = torch.rand(batch, generator=generator, device=_draw_device(generator), dtype=torch.float64)
    return _cpu(u.mul_(high - low).add_(low))


def choice(values: Sequence[Any] | Tensor, batch: int, generator: torch.Generator | None) -> Tensor:
    """``batch`` uniform draws from ``values`` (a 1-D tensor or sequence), on the CPU."""
    values = torch.as_tensor(values)
    index = torch.randint(len(values), (batch,), generator=generator, device=_draw_device(generator))
    return values[_cpu(index)]


def bernoulli(p: float, batch: int, generator: torch.Generator | None) -> Tensor:
    """``batch`` Bernoulli(p) draws as a bool CPU tensor."""
    return uniform(0.0, 1.0, batch, generator) < p


def integers(high: Tensor | int, batch: int, generator: torch.Generator | None) -> Tensor:
    """``batch`` uniform integers in ``[0, high)`` (``high`` a number or (B,) tensor >= 1), int64 CPU."""
    u = uniform(0.0, 1.0, batch, generator)
    high_t = torch.as_tensor(high, dtype=torch.float64)
    return torch.minimum((u * high_t).floor(), high_t - 1).to(torch.int64)


def seeds(batch: int, generator: torch.Generator | None) -> Tensor:
    """``batch`` independent 63-bit seeds (int64, CPU), one per sample."""
    return _cpu(draw_seeds(batch, generator))  # the one seed draw, also the dispatchers' (functional._random)


def _cpu(tensor: Tensor) -> Tensor:
    """``tensor`` on the CPU (a draw from an accelerator generator is copied once)."""
    return tensor if tensor.device.type == "cpu" else tensor.cpu()


# --------------------------------------------------------------------------- groups

GroupFn = Callable[[Tensor, Tensor], Tensor]


AnyGroupFn = Callable[[Any, Tensor], Any]


@overload
def apply_by_group(frames: Tensor, group: Tensor, functions: Sequence[GroupFn | None]) -> Tensor: ...
@overload
def apply_by_group(frames: EventBatch, group: Tensor, functions: Sequence[AnyGroupFn | None]) -> EventBatch: ...
@overload
def apply_by_group(
    frames: Tensor | EventBatch, group: Tensor, functions: Sequence[AnyGroupFn | None]
) -> Tensor | EventBatch: ...
def apply_by_group(frames: Tensor | EventBatch, group: Tensor, functions: Sequence[AnyGroupFn | None]) -> Any:
    """Apply ``functions[g]`` to the samples whose ``group`` is ``g``; ``None`` keeps them.

    Each function gets the sub-batch and the (CPU) indices of its samples, and is called
    even on an empty sub-batch, so the output dtype (promoted over every branch) does not
    depend on the random draw. Samples are gathered once per group, not looped over. The
    groups are read on the host (``group`` is a CPU tensor from ``make_params``): no host
    synchronisation, and a group that holds the whole batch is not gathered at all.

    Args:
        frames: batch ``(B, T, 2, H, W)``.
        group: ``(B,)`` integer CPU tensor with values in ``[0, len(functions))``.
        functions: one callable ``(sub_batch, indices) -> sub_batch`` or ``None`` per group.
    """
    if isinstance(frames, EventBatch):
        return _apply_by_group_events(frames, group, functions)
    device = frames.device
    batch = frames.shape[0]
    labels = np.asarray(group.tolist(), dtype=np.int64).reshape(batch)
    results: list[tuple[Tensor | None, int, Tensor]] = []
    out_dtype = frames.dtype if any(f is None for f in functions) else None
    for g, function in enumerate(functions):
        if function is None:
            continue
        members = np.flatnonzero(labels == g)
        index = torch.from_numpy(members)
        on_device = None
        if members.size == batch:
            sub = frames
        elif members.size == 0:
            sub = frames[:0]
        else:
            on_device = index.to(device)
            sub = frames.index_select(0, on_device)
        result = function(sub, index)
        if result.shape[1:] != frames.shape[1:]:
            raise ValueError(
                f"every branch must keep the frames' shape {tuple(frames.shape[1:])}, "
                f"got {tuple(result.shape[1:])}"
            )
        if out_dtype is None:
            out_dtype = result.dtype
        elif result.dtype != out_dtype:
            out_dtype = torch.promote_types(out_dtype, result.dtype)
        results.append((on_device, int(members.size), result))
    if out_dtype is None:
        raise ValueError("apply_by_group needs at least one function or None")

    def cast(tensor: Tensor) -> Tensor:
        return tensor if tensor.dtype == out_dtype else tensor.to(out_dtype)

    for _, size, result in results:
        if size == batch:
            return cast(result)
    covered = sum(size for _, size, _ in results)
    out = frames.to(out_dtype, copy=True) if covered < batch else torch.empty(frames.shape, dtype=out_dtype, device=device)
    for on_device, size, result in results:
        if on_device is not None:  # a proper, non-empty subset (a whole batch returned above)
            out.index_copy_(0, on_device, cast(result))
    return out


def _apply_by_group_events(batch: EventBatch, group: Tensor, functions: Sequence[AnyGroupFn | None]) -> EventBatch:
    """:func:`apply_by_group` for an :class:`EventBatch`: streams gathered by slices of the
    (CPU) offsets, results put back in stream order; no host synchronisation."""
    size = len(batch)
    labels = np.asarray(group.tolist(), dtype=np.int64).reshape(size)
    parts: list[tuple[list[int], EventBatch]] = []
    for g, function in enumerate(functions):
        members = np.flatnonzero(labels == g)
        index = torch.from_numpy(members)
        if function is None:
            if members.size:
                parts.append((members.tolist(), batch if members.size == size else batch.index_select(index)))
            continue
        sub = batch if members.size == size else batch.index_select(index)
        result = function(sub, index)
        if not isinstance(result, EventBatch):
            raise TypeError(
                f"every branch must return an EventBatch for EventBatch input, got {type(result).__name__} "
                "(bin with EventsToFrames outside OneOf/RandomApply)"
            )
        if members.size == size:
            return result
        if members.size:
            parts.append((members.tolist(), result))
    if not parts:
        return batch
    return merge_streams(parts, size, batch)


def _events_by_group(video: Tensor, group: Tensor, functions: Sequence[Callable[[Tensor, Tensor], EventBatch]]) -> EventBatch:
    """``functions[g]`` (video in, events out) on the videos whose ``group`` is ``g``, the streams put
    back in the batch's order; the (CPU) groups are read on the host, a group that holds the whole
    batch is not gathered, and an empty batch gives the first function's empty result."""
    size = video.shape[0]
    labels = np.asarray(group.tolist(), dtype=np.int64).reshape(size)
    parts: list[tuple[list[int], EventBatch]] = []
    for g, function in enumerate(functions):
        members = np.flatnonzero(labels == g)
        if members.size == size:
            return function(video, torch.from_numpy(members))
        if members.size:
            index = torch.from_numpy(members)
            parts.append((members.tolist(), function(video.index_select(0, index_on(index, video.device)), index)))
    if not parts:
        return functions[0](video, torch.zeros(0, dtype=torch.int64))
    return merge_streams(parts, size, parts[0][1])


def _take(inputs: Tensor | EventBatch, index: np.ndarray) -> Any:
    """Samples ``index`` (host indices) of frames or an EventBatch; the whole batch is not copied."""
    if index.size == len(inputs) and (index == np.arange(index.size)).all():
        return inputs
    rows = torch.from_numpy(np.ascontiguousarray(index, dtype=np.int64))
    if isinstance(inputs, EventBatch):
        return inputs.index_select(rows)
    return inputs.index_select(0, index_on(rows, inputs.device))


def _put_back(inputs: Tensor | EventBatch, kept: np.ndarray, result: Any) -> Any:
    """``inputs`` with samples ``kept`` replaced by ``result`` (promoted to a common dtype)."""
    b = len(inputs)
    if kept.size == b:
        return result
    if isinstance(inputs, EventBatch):
        return replace_streams(inputs, kept, result)
    dtype = torch.promote_types(inputs.dtype, result.dtype)
    out = inputs.to(dtype, copy=True)
    if kept.size:
        out.index_copy_(0, index_on(torch.from_numpy(kept), inputs.device), result if result.dtype == dtype else result.to(dtype))
    return out


def _select(gate: Tensor, result: Tensor, inputs: Tensor) -> Tensor:
    """``result`` where ``gate`` (B,) is on, ``inputs`` elsewhere, in the promoted dtype (no host read)."""
    dtype = torch.promote_types(inputs.dtype, result.dtype)
    on = gate.to(device=result.device, dtype=torch.bool).view(-1, *([1] * (result.dim() - 1)))
    return torch.where(on, result if result.dtype == dtype else result.to(dtype), inputs if inputs.dtype == dtype else inputs.to(dtype))


# --------------------------------------------------------------------------- base


class EventTransform(nn.Module):
    """Base class: an ``nn.Module`` mapping event frames to event frames.

    Subclasses override :meth:`sample_params` (draw per-sample parameters on the CPU, no
    state) and :meth:`apply_transform` (call a private kernel on a checked batch). Calling a module
    accepts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)`` frames and returns the same layout on
    the same device (see the module docstring for extra inputs and dicts).

    Args:
        p: probability that a sample is transformed; the others pass unchanged. Drawn
            per sample in :meth:`make_params` (entry ``"apply"``) when ``p < 1``.

    Shape:
        ``(T, 2, H, W)`` or ``(B, T, 2, H, W)`` frames, or an :class:`~event_transforms.EventBatch`
        for a subclass with an event kernel; each subclass states its output.

    Example:
        >>> import event_transforms as et
        >>> rotation = et.RandomRotation(30.0, p=0.5)
        >>> frames = torch.poisson(torch.full((4, 6, 2, 9, 11), 0.3))
        >>> params = rotation.make_params(frames.shape, generator=torch.Generator().manual_seed(0))
        >>> sorted(params), params["apply"].tolist()
        (['angle', 'apply'], [False, False, True, True])
        >>> _ = torch.manual_seed(123)  # the global RNG does not matter when params are given
        >>> torch.equal(rotation(frames, params=params), rotation(frames, params=params))
        True
    """

    #: Declared by transforms that read other samples of the batch or the labels (CutMix,
    #: MixUp) and by containers holding one. A coupled transform sees the whole batch (or,
    #: gated, the kept samples with their partners: :attr:`partner_key`) and its labels go
    #: through :meth:`apply_labels`; ``OneOf`` and ``RandomApply`` refuse it by name,
    #: because they hand their members sub-batches. It is exempt from per-sample purity
    #: (a sample alone cannot equal the sample mixed with a partner of its batch).
    couples_samples: bool = False

    #: For a coupled transform, the params entry that names each sample's partner (an
    #: index into the batch). The gate gathers the samples it keeps together with the
    #: partners they read, so a partner that is itself gated off is still read, unchanged.
    partner_key: str | None = None

    #: Declared by a transform whose kernels take the gate as their own per-sample flags (the
    #: flips, time reversal, polarity swap: a kernel that leaves an unflagged sample unchanged
    #: and keeps the dtype). ``apply_transform`` then gets the whole batch and the tree with
    #: ``params["apply"]`` and hands the gate to the kernel: the one rule's result, without the
    #: gather and put-back, for kernels whose work is per element or per event.
    gates_in_kernel: bool = False

    #: For a dict input, the entry holding the labels a coupled transform mixes (``None``:
    #: dict inputs pass their labels through). Ignored by transforms that are not coupled.
    label_key: str | None = None

    def __init__(self, *, p: float = 1.0) -> None:
        super().__init__()
        self.p = check_probability(p, "p")

    def forward(
        self,
        *inputs: Any,
        generator: torch.Generator | None = None,
        params: Params | None = None,
        metadata: Mapping[str, Any] | Sequence[Mapping[str, Any]] | None = None,
    ) -> Any:
        """Transform the frames among ``inputs``; everything else passes through.

        Args:
            inputs: frames ``(T, 2, H, W)`` or ``(B, T, 2, H, W)`` (a tensor, a
                ``tv_tensors.Video``, a numpy array — tonic's ``ToFrame`` and
                ``DiskCachedDataset`` output, converted once here with
                ``torch.from_numpy``, the result a tensor — or a dict holding them under
                ``"frames"``), then
                anything (labels, ...), returned unchanged, except that a transform that
                :attr:`couples_samples` mixes the second input (or the dict's
                :attr:`label_key` entry), the labels, through :meth:`apply_labels`.
            generator: source of the parameter draws, a ``torch.Generator`` or ``None``
                (a CPU generator keeps CUDA calls free of host synchronisation); ``None``
                uses torch's global RNG, so each DataLoader worker draws differently.
            params: a tree returned by :meth:`make_params`, to replay a draw. It is
                checked here, once, against :meth:`params_spec` (recursively through
                containers); the error names the module, the key and the value.
            metadata: per-sample information some transforms read (e.g. object sizes):
                a dict of numbers or ``(B,)`` values, or a list of dicts (one per sample).
                For a dict input, its other entries are the metadata unless given here.

        Returns:
            The transformed frames in the input's form: a tensor, a ``Video``, a dict
            with ``"frames"`` replaced, or a tuple ``(frames, *rest)`` for several inputs.

        Raises:
            TypeError: ``generator`` is not a ``torch.Generator`` or ``None``; a params
                leaf of the wrong kind.
            ValueError: a params entry missing, unknown, of the wrong shape or out of range.
        """
        if not inputs:
            raise TypeError(f"{type(self).__name__} needs frames as its first input, got no inputs")
        if generator is not None and not isinstance(generator, torch.Generator):
            raise TypeError(
                f"{type(self).__name__}: generator must be a torch.Generator or None, got {type(generator).__name__} "
                f"{generator!r}"
            )
        first, rest = inputs[0], inputs[1:]
        if self.takes_video:  # a video in, events out (EmulateEvents, or a container that starts with it)
            if not isinstance(first, Tensor):
                raise TypeError(f"{type(self).__name__} takes a video as a torch.Tensor, got {type(first).__name__}")
            shape = self.video_shape(first.shape)
            video = first if first.dim() == len(shape) else first.unsqueeze(0)
            if params is None:
                params = self.make_params(shape, generator=generator, metadata=metadata)
            else:
                with torch.profiler.record_function(CHECK_RANGE):
                    params = self._check_params(params, shape)
            events = self._run(video, params)
            return (events, *rest) if rest else events
        if isinstance(first, EventBatch) and not self.takes_events:
            if params is None:
                params = self.make_params(first.frame_shape, generator=generator, metadata=metadata)
            else:
                with torch.profiler.record_function(CHECK_RANGE):
                    params = self._check_params(params, first.frame_shape)
            moved = self._run(first, params)
            if self.couples_samples and rest:  # the labels, mixed as on frames
                rest = (self._mix_labels(rest[0], params, False, len(first)), *rest[1:])
            return (moved, *rest) if rest else moved
        if self.takes_events:
            first = self.events_to_frames(first)  # events in, frames from here on
        frames = first
        if isinstance(first, Mapping):
            if FRAMES_KEY not in first:
                raise ValueError(
                    f"a dict input must hold the frames under {FRAMES_KEY!r}, got keys {sorted(first)}"
                )
            frames = first[FRAMES_KEY]
            if metadata is None:
                metadata = {k: v for k, v in first.items() if k != FRAMES_KEY}
        frames = _numpy_frames(frames)
        video = _video_of(frames)
        like = frames if video is not None else None
        if video is not None:
            frames = frames.as_subclass(Tensor)
        batch, unbatch = as_batch(check_frames(frames))
        if params is None:
            params = self.make_params(batch.shape, generator=generator, metadata=metadata)
        else:
            with torch.profiler.record_function(CHECK_RANGE):
                params = self._check_params(params, check_shape(batch.shape))
        out = unbatch(self._run(batch, params) if batch.device.type != "meta" else self._run_meta(batch, params))
        if like is not None:
            out = video.wrap(out, like=like)
        if self.couples_samples:
            single = batch.dim() != frames.dim()
            if isinstance(first, Mapping) and self.label_key is not None:
                if self.label_key not in first:
                    raise ValueError(
                        f"{type(self).__name__}: label_key {self.label_key!r} is not in the input dict (keys {sorted(first)})"
                    )
                first = {**first, self.label_key: self._mix_labels(first[self.label_key], params, single, batch.shape[0])}
            elif rest:
                rest = (self._mix_labels(rest[0], params, single, batch.shape[0]), *rest[1:])
        result: Any = {**first, FRAMES_KEY: out} if isinstance(first, Mapping) else out
        return (result, *rest) if rest else result

    def _check_params(self, params: Params, shape: torch.Size) -> Params:
        """:func:`check_tree`, with meta-device leaves (which hold no values to apply) refused by name."""
        stack: list[tuple[str, Any]] = [("params", params)]
        while stack:
            path, node = stack.pop()
            if isinstance(node, Mapping):
                stack.extend((f"{path}[{key!r}]", value) for key, value in node.items())
            elif isinstance(node, Tensor) and node.device.type == "meta":
                raise ValueError(
                    f"{type(self).__name__}: {path} is on the meta device, which holds no values to apply; "
                    "pass the CPU tree make_params returns"
                )
        return check_tree(self, params, shape)

    def _run_meta(self, batch: Tensor, params: Params) -> Tensor:
        """:meth:`_run` on meta-device frames (shapes only): a transform that must read the
        frames' values (exact TES, count checks) cannot run there and says so by name."""
        try:
            return self._run(batch, params)
        except NotImplementedError as error:
            raise ValueError(
                f"{type(self).__name__} reads the values of the frames, which frames on the meta device do not "
                f"hold (frames of shape {tuple(batch.shape)} on device 'meta'); run it on real frames"
            ) from error

    def _mix_labels(self, labels: object, params: Params, single: bool, size: int) -> Any:
        """Check the labels of a coupled call (batch first) and hand them to :meth:`apply_labels`."""
        if not isinstance(labels, Tensor):
            raise TypeError(
                f"{type(self).__name__} mixes the second input, the labels: expected a tensor, got {type(labels).__name__}"
            )
        batch = labels.unsqueeze(0) if single else labels
        if batch.dim() == 0 or batch.shape[0] != size:
            raise ValueError(
                f"{type(self).__name__}: labels must have the batch size {size} first, got shape {tuple(labels.shape)}"
            )
        mixed = self._run_labels(batch, params)
        return mixed.squeeze(0) if single else mixed

    def apply_labels(self, labels: Tensor, params: Params) -> Tensor:
        """Hook: the labels ``(B, ...)`` of a call with parameters ``params`` (identity).

        Called by :meth:`forward` only for a transform that :attr:`couples_samples`, on
        the whole batch, after :meth:`apply_transform`; CutMix and MixUp mix the labels here with
        the partners and weights of their ``params``; containers chain their members'.
        """
        return labels

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "apply" in cls.__dict__:
            raise TypeError(
                f"{cls.__name__} defines apply: the hook is apply_transform(inputs, params) (apply is "
                "torch.nn.Module.apply, which a transform keeps); rename the method")
        if cls.sample_params is not EventTransform.sample_params and cls.params_spec is EventTransform.params_spec:
            raise TypeError(
                f"{cls.__name__} draws parameters (it overrides sample_params), so it must declare them: "
                "override params_spec to return a dict of Param, one per key sample_params returns"
            )

    def params_spec(self, shape: torch.Size) -> Spec:
        """Override (required with :meth:`sample_params`): describe this module's params dict.

        Returns a dict mapping each key :meth:`sample_params` returns for a batch ``shape``
        to a :class:`Param` (kind, trailing shape, range), and each child's
        key to ``(child, child_shape)`` for containers. The gate ``"apply"`` is added by the
        base class. A module that draws nothing inherits ``{}`` (it takes only the gate); a
        subclass that overrides :meth:`sample_params` without this is refused when the class
        is defined. ``module(x, params=tree)`` checks the tree against it and nothing else.
        """
        return {}

    def make_params(
        self,
        shape: Sequence[int],
        *,
        generator: torch.Generator | None = None,
        metadata: Mapping[str, Any] | Sequence[Mapping[str, Any]] | None = None,
    ) -> Params:
        """Draw every random number of one call on a batch of ``shape`` ``(B, T, 2, H, W)``.

        Returns a dict of ``(B, ...)`` CPU tensors (nested for containers). Give it back as
        ``module(frames, params=...)`` to replay the call exactly.
        """
        shape = self.video_shape(shape) if self.takes_video else check_shape(shape)
        if generator is not None and not isinstance(generator, torch.Generator):
            raise TypeError(
                f"{type(self).__name__}.make_params: generator must be a torch.Generator or None, got "
                f"{type(generator).__name__} {generator!r}"
            )
        params = self.sample_params(shape, generator=generator, metadata=metadata)
        if self.p < 1:
            params["apply"] = bernoulli(self.p, shape[0], generator)
        return params

    def sample_params(
        self,
        shape: torch.Size,
        *,
        generator: torch.Generator | None = None,
        metadata: Mapping[str, Any] | Sequence[Mapping[str, Any]] | None = None,
    ) -> Params:
        """Override: this transform's own parameters for a checked batch ``shape``."""
        return {}

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:  # pragma: no cover
        """Override: transform a checked batch ``(B, T, 2, H, W)`` or an EventBatch with given
        parameters, by calling the operation's kernels through the registry:
        ``call_kernel(F.rotate, inputs, params["angle"], ...)``
        (:func:`~event_transforms.functional._dispatch.call_kernel`).

        kornia names this hook ``apply_transform`` too; ``module.apply(fn)`` stays
        :meth:`torch.nn.Module.apply`. A subclass that defines ``apply`` (the hook's name up to
        0.1) is refused with a :class:`TypeError` when the class is defined."""
        raise NotImplementedError

    def output_shape(self, shape: torch.Size) -> torch.Size:
        """The batch shape this transform returns for input ``shape`` (the same by default)."""
        return shape

    def _dispatch(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        """:meth:`apply_transform` on frames or an EventBatch; an operation with no kernel for the input's
        type is refused with this module's name."""
        try:
            return self.apply_transform(inputs, params)
        except NoKernelError as error:
            raise TypeError(f"{type(self).__name__} {error.detail}") from None

    @property
    def takes_events(self) -> bool:
        """Whether a call's first input is an event stream, not frames.

        True for :class:`~event_transforms.EventsToFrames` and for a ``Compose`` that
        starts with one: ``forward`` then makes the frames with :meth:`events_to_frames`
        before drawing parameters, and the rest of the call sees frames.
        """
        return False

    def events_to_frames(self, events: Any) -> Tensor:
        """Override with :attr:`takes_events`: turn a call's first input into frames."""
        raise TypeError(f"{type(self).__name__} takes frames, not events")

    @property
    def takes_video(self) -> bool:
        """Whether a call's first input is a video (luminance or RGB frames) and its output events.

        True for :class:`~event_transforms.EmulateEvents` and for a container that starts with
        one (a ``Compose`` whose first member, a ``OneOf`` whose every member takes a video):
        ``forward`` draws the parameters for :meth:`video_shape` and the output is an
        :class:`~event_transforms.EventBatch`.
        """
        return False

    def video_shape(self, shape: Sequence[int]) -> torch.Size:
        """Override with :attr:`takes_video`: the batched video shape of a call on ``shape``
        (a single video gains the batch axis), checked."""
        raise TypeError(f"{type(self).__name__} takes event frames, not a video")

    @overload
    def _run(self, frames: Tensor, params: Params) -> Tensor: ...
    @overload
    def _run(self, frames: EventBatch, params: Params) -> EventBatch: ...
    @overload
    def _run(self, frames: Tensor | EventBatch, params: Params) -> Tensor | EventBatch: ...
    def _run(self, frames: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        """Apply to a checked batch, honouring the per-sample gate ``params["apply"]``.

        The one gating rule, for every module and both input types: the samples the gate
        keeps are gathered (with the partners they read, for a transform with a
        :attr:`partner_key`), the kernel runs once on them, and they are put back; the
        others come back unchanged (promoted to the output dtype). Kernels never see the
        gate. The gate is a CPU tensor from ``make_params``, read on the host: no sync.
        Where it should not be read (frames traced by ``torch.compile``, or frames with a
        gate the caller moved to an accelerator) the same rule is evaluated without reading
        it: the kernel runs on the whole batch and the gate selects, sample by sample, its
        result or the input (equal results, by per-sample purity; no data-dependent shapes).
        An EventBatch's gate is always read (once, a sync if it is on an accelerator). A
        transform that :attr:`gates_in_kernel` gets the whole batch and the gate instead."""
        if self.gates_in_kernel and not self.couples_samples:
            return self._dispatch(frames, params)
        gate = params.get("apply")
        if gate is not None and isinstance(frames, Tensor) and (
            torch.compiler.is_compiling() or gate.device.type != "cpu"
        ):
            return _select(gate, cast(Tensor, self._dispatch(frames, params)), frames)
        kept = self._kept(params)
        if kept is None:
            return self._dispatch(frames, params)
        if self.couples_samples:
            needed, sub_params, rows = self._with_partners(params, kept)
        else:
            needed, sub_params, rows = kept, slice_params(params, torch.from_numpy(kept)), None
        result = self._dispatch(_take(frames, needed), sub_params)
        return _put_back(frames, kept, result if rows is None else _take(result, rows))

    def _kept(self, params: Params) -> np.ndarray | None:
        """The samples the gate keeps (host indices), or ``None`` when it keeps every one."""
        gate = params.get("apply")
        if gate is None:
            return None
        on = np.asarray(gate.tolist(), dtype=bool).reshape(-1)
        return None if on.all() else np.flatnonzero(on)

    def _with_partners(self, params: Params, kept: np.ndarray) -> tuple[np.ndarray, Params, np.ndarray]:
        """For a gated coupled call: the samples to gather (kept and their partners, in batch
        order), their params with the partners renumbered into that sub-batch (a sample
        gathered only as a partner is its own partner: its result is not used), and the
        rows of the kept samples in the sub-batch."""
        if self.partner_key is None:
            raise TypeError(
                f"{type(self).__name__} couples samples and has p={self.p} < 1, so it must name the params entry of its "
                "partners in partner_key (the gate gathers the kept samples with the partners they read)"
            )
        partner = np.asarray(params[self.partner_key].tolist(), dtype=np.int64).reshape(-1)
        needed = np.union1d(kept, partner[kept]).astype(np.int64)
        position = np.full(partner.shape[0], -1, dtype=np.int64)
        position[needed] = np.arange(needed.size)
        renumbered = position[partner[needed]]
        is_kept = np.zeros(partner.shape[0], dtype=bool)
        is_kept[kept] = True
        renumbered = np.where(is_kept[needed], renumbered, np.arange(needed.size))
        sub_params = slice_params(params, torch.from_numpy(needed))
        sub_params[self.partner_key] = torch.from_numpy(renumbered)
        return needed, sub_params, position[kept]

    def _run_labels(self, labels: Tensor, params: Params) -> Tensor:
        """:meth:`apply_labels` under the gate, by the rule of :meth:`_run`: the kept samples'
        labels mixed with their partners', the others' as :meth:`keep_labels` gives them."""
        gate = params.get("apply")
        if gate is not None and (torch.compiler.is_compiling() or gate.device.type != "cpu"):
            return _select(gate, self.apply_labels(labels, params), self.keep_labels(labels))
        kept = self._kept(params)
        if kept is None:
            return self.apply_labels(labels, params)
        needed, sub_params, rows = self._with_partners(params, kept)
        mixed = self.apply_labels(_take(labels, needed), sub_params)
        return _put_back(self.keep_labels(labels), kept, _take(mixed, rows))

    def keep_labels(self, labels: Tensor) -> Tensor:
        """Hook: the labels ``(B, ...)`` of samples the gate skips, in the form
        :meth:`apply_labels` returns (unchanged by default; CutMix/MixUp turn class indices
        into one-hot targets)."""
        return labels

    def extra_repr(self) -> str:
        settings = self._settings()
        if self.p < 1:
            settings = f"{settings}, p={self.p}" if settings else f"p={self.p}"
        return settings

    def _settings(self) -> str:
        """Override: the settings shown in ``repr`` (``p`` is added by the base class)."""
        return ""



class Lambda(EventTransform):
    """A plain function of frames as a transform: ``function(frames) -> frames``.

    :func:`as_transform` wraps anything that is not an :class:`EventTransform` in one, so
    containers and data sets call every member the same way. The function draws no
    parameters (its tree entry is empty) and is called on the whole batch
    ``(B, T, 2, H, W)``; it must keep the shape.

    Args:
        function: ``frames -> frames``, shape kept (a torchvision transform works).

    Shape:
        ``(B, T, 2, H, W)`` in and out (a single ``(T, 2, H, W)`` sequence is given a batch
        dimension first, as for every transform).

    Example:
        >>> double = Lambda(lambda frames: 2 * frames)
        >>> double(torch.ones(1, 2, 1, 1)).flatten().tolist()
        [2.0, 2.0]
    """

    def __init__(self, function: Callable[[Tensor], Tensor]) -> None:
        super().__init__()
        if not callable(function):
            raise TypeError(f"function must be callable, got {type(function).__name__}")
        self.function = function

    def params_spec(self, shape: torch.Size) -> Spec:
        return {}

    def apply_transform(self, frames: Tensor | EventBatch, params: Params) -> Tensor:
        if isinstance(frames, EventBatch):
            raise NoKernelError("", events=True, detail="has no kernel for an EventBatch; bin the events first with "
                                "EventsToFrames (it can stand anywhere in a Compose)")
        out = self.function(frames)
        if not isinstance(out, Tensor) or out.shape != frames.shape:
            got = tuple(out.shape) if isinstance(out, Tensor) else type(out).__name__
            raise ValueError(
                f"Lambda({self._settings() or 'function'}) must keep the batch shape {tuple(frames.shape)}, got {got}; "
                "a member of a pipeline may change the values, not the number or size of the frames"
            )
        return out

    def _settings(self) -> str:
        if isinstance(self.function, nn.Module):
            return ""  # shown as a child module
        return getattr(self.function, "__name__", None) or repr(self.function)


def as_transform(transform: object, name: str = "transform") -> EventTransform:
    """``transform`` if it is an :class:`EventTransform`, else a :class:`Lambda` around it.

    ``torch.from_numpy`` and ``torch.as_tensor`` become a pass-through: a container
    converts numpy frames once, before its members run.

    Args:
        transform: an event transform, or a callable ``frames -> frames``.
        name: what to call ``transform`` in the error message.

    Raises:
        TypeError: ``transform`` is not callable.

    Example:
        >>> as_transform(torch.neg)
        Lambda(neg)
        >>> as_transform(3, name="transforms[1]")
        Traceback (most recent call last):
        ...
        TypeError: transforms[1] must be an EventTransform or a callable, got int
    """
    if isinstance(transform, EventTransform):
        return transform
    if transform is torch.from_numpy or transform is torch.as_tensor:
        # Compose([torch.from_numpy, ...]): the container converts numpy frames once, before
        # its members run, so the member would get a tensor; it passes the frames through.
        return Lambda(_passthrough)
    if not callable(transform):
        raise TypeError(f"{name} must be an EventTransform or a callable, got {type(transform).__name__}")
    return Lambda(transform)
