"""Mixing kernels: Cutout (a box emptied), CutMix (a box pasted from a partner) and MixUp
(a convex blend with a partner), and the label mixing that goes with them.

Boxes are per sample, the same in every frame of a sequence, given as ``(B,)`` integer
``top, left, height, width`` already clipped to the frame. Partners are ``(B,)`` indices into
the same batch. Cutout and CutMix move whole counts (dtype kept); MixUp blends values
(input dtype for float input, float32 for integer input).

On an EventBatch the kernels (``<op>_events``) keep or take whole events: Cutout drops
the events in the box, CutMix takes the partner's events in the box instead of the
sample's own, MixUp keeps each own event with probability w and takes each of the
partner's with probability 1 - w (counter-based draws keyed by the sample's seed), so
binned, its frames equal the frame MixUp's in expectation (each entry's mean is
``w·x + (1 - w)·x'``) while staying whole counts. A stream's output holds its own kept
events first, then those taken from its partner; with a frame grid, a partner's events are
moved onto the sample's grid (by ``t_start[b] - t_start[partner]``), so binned, they land
in the frames the frame kernel pastes them into. A sample that is its own partner is
left as it is (frames: pasting or blending a sample with itself is the identity).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from .._params import SEED, Param, check_args
from .._validation import describe
from ..events.batch import EventBatch
from ._frame_ops import blend_labels, check_classes
from ._dispatch import batch_of, kernel_for, register_kernel, shape_of
from ._event_ops import _compact
from ._random import draw_seeds, sample_salts, uniform

__all__ = [
    "cutout", "cutout_frames", "cutout_events", "cutmix", "cutmix_frames", "cutmix_events",
    "mixup", "mixup_frames", "mixup_events", "mix_labels",
]

Scalars = float | Sequence[float] | Tensor


def _box_mask(
    top: Tensor, left: Tensor, height: Tensor, width: Tensor, size: Sequence[int], device: torch.device
) -> Tensor:
    """(B, 1, 1, H, W) bool: True inside each sample's box."""
    h, w = size
    rows = torch.arange(h, device=device)
    cols = torch.arange(w, device=device)
    top, left = top.to(device, non_blocking=True).unsqueeze(1), left.to(device, non_blocking=True).unsqueeze(1)
    inside_rows = (rows >= top) & (rows < top + height.to(device, non_blocking=True).unsqueeze(1))
    inside_cols = (cols >= left) & (cols < left + width.to(device, non_blocking=True).unsqueeze(1))
    return (inside_rows.unsqueeze(2) & inside_cols.unsqueeze(1)).unsqueeze(1).unsqueeze(1)


# --------------------------------------------------------------------------- declarations
# Each operation's per-sample arguments, declared once: the dispatcher checks its arguments
# against it (check_args), the module's params_spec returns it (check_tree).


#: :func:`cutout`'s box: first row and column, height and width, non-negative (a box past the
#: border stops there).
CUTOUT_SPEC = {name: Param("int", low=0) for name in ("top", "left", "height", "width")}


def mix_labels_spec(batch: int) -> dict[str, Param]:
    """:func:`mix_labels`'s partner (a sample index in [0, B)) and the sample's own share ``weight`` in [0, 1]."""
    return {"partner": Param("int", low=0, high=batch - 1), "weight": Param("float", low=0.0, high=1.0)}


def cutmix_spec(shape: Sequence[int]) -> dict[str, Param]:
    """:func:`cutmix`'s partner in [0, B) and box (as :data:`CUTOUT_SPEC`) for a batch ``shape``."""
    return {"partner": mix_labels_spec(shape[0])["partner"], **CUTOUT_SPEC}


def mixup_spec(shape: Sequence[int]) -> dict[str, Param]:
    """:func:`mixup`'s partner, weight (as :func:`mix_labels_spec`) and, on events, seed."""
    return {**mix_labels_spec(shape[0]), "seed": SEED}


def cutout(frames: Tensor | EventBatch, top: Scalars, left: Scalars, height: Scalars, width: Scalars) -> Tensor | EventBatch:
    """Empty a box of every frame of each sequence (DeVries & Taylor's Cutout, used by NDA).

    The box is the same in all frames of a sequence; a box past the border stops there.
    Counts outside it and the dtype are kept. On an EventBatch (:func:`cutout_events`) the
    events in the box are removed (binned, equal to the frame kernel's result).

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch.
        top, left: the box's first row and column, integers >= 0 or ``(B,)``.
        height, width: its size in pixels.

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: same shape, dtype and device.
        - top, left, height, width: integers or ``(B,)``.

    Example:
        >>> cutout(torch.ones(1, 2, 3, 4, dtype=torch.int16), 1, 1, 2, 2)[0, 0].tolist()
        [[1, 1, 1, 1], [1, 0, 0, 1], [1, 0, 0, 1]]
    """
    kernel = kernel_for(cutout, frames)
    batch, b, unbatch = batch_of(frames)
    box = check_args("cutout", CUTOUT_SPEC, b, top=top, left=left, height=height, width=width)
    return unbatch(kernel(batch, box["top"], box["left"], box["height"], box["width"]))


@register_kernel(cutout, Tensor)
def cutout_frames(batch: Tensor, top: Tensor, left: Tensor, height: Tensor, width: Tensor) -> Tensor:
    """Kernel of :func:`cutout` for frames: empty the box ``top, left, height, width`` of each sample.

    Args:
        batch: frames ``(B, T, 2, H, W)``.
        top, left, height, width: ``(B,)`` integer boxes.

    Shape:
        - batch: ``(B, T, 2, H, W)``.
        - output: same shape, dtype and device.

    Example:
        >>> box = torch.tensor([1])
        >>> int(cutout_frames(torch.ones(1, 1, 2, 3, 3), box, box, box, box).sum())
        16
    """
    mask = _box_mask(top, left, height, width, batch.shape[-2:], batch.device)
    return batch.masked_fill(mask, 0)


def cutmix(
    frames: Tensor | EventBatch, partner: Scalars, top: Scalars, left: Scalars, height: Scalars, width: Scalars
) -> Tensor | EventBatch:
    """Paste a box of each sample's partner (all frames) into the sample (Yun et al.'s CutMix).

    Sample b takes the box ``[top, top + height) × [left, left + width)`` from sample
    ``partner[b]`` of the same batch, in every frame and polarity. Counts are moved, not
    interpolated: the dtype is kept. Mix the labels with :func:`mix_labels` and the weight
    ``1 - height·width / (H·W)`` (the share of the sample's own pixels).

    On an EventBatch (:func:`cutmix_events`) the sample's events in the box are replaced by
    the partner's events in the box (see the module docstring): binned, equal to the frame
    kernel's result.

    Args:
        frames: a batch ``(B, T, 2, H, W)`` (or one sequence, its own partner), or an EventBatch.
        partner: ``(B,)`` sample indices in ``[0, B)``.
        top, left, height, width: the box per sample, as in :func:`cutout`.

    Shape:
        - frames: ``(B, T, 2, H, W)`` (or ``(T, 2, H, W)``).
        - partner: ``(B,)``; top, left, height, width: integers or ``(B,)``.
        - output: the frames' shape, dtype and device.

    Example:
        >>> frames = torch.stack([torch.zeros(1, 2, 2, 3), torch.ones(1, 2, 2, 3)])
        >>> cutmix(frames, [1, 0], 0, 1, 2, 1)[0, 0, 0].tolist()
        [[0.0, 1.0, 0.0], [0.0, 1.0, 0.0]]
    """
    kernel = kernel_for(cutmix, frames)
    batch, b, unbatch = batch_of(frames)
    args = check_args("cutmix", cutmix_spec(shape_of(batch)), b, partner=partner, top=top, left=left, height=height, width=width)
    return unbatch(kernel(batch, args["partner"], args["top"], args["left"], args["height"], args["width"]))


@register_kernel(cutmix, Tensor)
def cutmix_frames(batch: Tensor, partner: Tensor, top: Tensor, left: Tensor, height: Tensor, width: Tensor) -> Tensor:
    """Kernel of :func:`cutmix` for frames: the box of sample b comes from sample ``partner[b]``.

    Args:
        batch: frames ``(B, T, 2, H, W)``.
        partner: ``(B,)`` indices of each sample's partner.
        top, left, height, width: ``(B,)`` integer boxes.

    Shape:
        - batch: ``(B, T, 2, H, W)``.
        - output: same shape, dtype and device.

    Example:
        >>> frames = torch.stack([torch.zeros(1, 2, 2, 2), torch.ones(1, 2, 2, 2)])
        >>> one = torch.tensor([1, 1])
        >>> cutmix_frames(frames, torch.tensor([1, 0]), one * 0, one * 0, one, one)[:, 0, 0].tolist()
        [[[1.0, 0.0], [0.0, 0.0]], [[0.0, 1.0], [1.0, 1.0]]]
    """
    mask = _box_mask(top, left, height, width, batch.shape[-2:], batch.device)
    return torch.where(mask, batch.index_select(0, partner.to(batch.device, non_blocking=True)), batch)


def mixup(
    frames: Tensor | EventBatch,
    partner: Scalars,
    weight: Scalars,
    *,
    seed: Scalars | None = None,
    generator: torch.Generator | None = None,
) -> Tensor | EventBatch:
    """Blend each sample with its partner: ``w · x_b + (1 - w) · x_partner[b]`` (Zhang et al.'s MixUp).

    On an EventBatch (:func:`mixup_events`) each of the sample's events is kept with
    probability ``w`` and each of the partner's taken with probability ``1 - w``, drawn from
    counter-based streams keyed by the sample's ``seed``: whole events, equal to the frame
    blend in expectation after binning (see the module docstring).

    Args:
        frames: a batch ``(B, T, 2, H, W)`` (or one sequence, its own partner), or an EventBatch.
        partner: ``(B,)`` sample indices in ``[0, B)``.
        weight: the sample's own share ``w`` in [0, 1], a number or ``(B,)``.
        seed: for an EventBatch, the per-sample seeds of the draws, an integer or ``(B,)``
            int64 in [0, 2**63) (default: drawn from ``generator``); unused on frames.
        generator: source of the seeds when ``seed`` is not given (``None``: torch's RNG).

    Returns:
        Blended frames: the input dtype for float input, float32 for integer input.

    Shape:
        - frames: ``(B, T, 2, H, W)`` (or ``(T, 2, H, W)``).
        - partner: ``(B,)``; weight: a number or ``(B,)``.
        - output: the frames' shape and device; float input keeps its dtype, integer input gives
          float32.

    Example:
        >>> frames = torch.stack([torch.zeros(1, 2, 1, 1), torch.ones(1, 2, 1, 1)]).to(torch.int32)
        >>> mixup(frames, [1, 0], [0.75, 0.5]).flatten().tolist()
        [0.25, 0.25, 0.5, 0.5]
    """
    kernel = kernel_for(mixup, frames)
    batch, b, unbatch = batch_of(frames)
    spec = mixup_spec(shape_of(batch))
    args = check_args("mixup", spec, b, partner=partner, weight=weight)
    if isinstance(batch, EventBatch):
        seeds = draw_seeds(b, generator).cpu() if seed is None else check_args("mixup", spec, b, seed=seed)["seed"]
        return kernel(batch, args["partner"], args["weight"], seeds)
    return unbatch(kernel(batch, args["partner"], args["weight"]))


@register_kernel(mixup, Tensor)
def mixup_frames(batch: Tensor, partner: Tensor, weight: Tensor, seed: Tensor | None = None) -> Tensor:
    """Kernel of :func:`mixup` for frames: ``weight[b] * x[b] + (1 - weight[b]) * x[partner[b]]``.

    Args:
        batch: frames ``(B, T, 2, H, W)``.
        partner: ``(B,)`` indices of each sample's partner.
        weight: ``(B,)`` mixing weights in [0, 1].
        seed: not used (the event kernel's draws; the blend draws nothing).

    Shape:
        - batch: ``(B, T, 2, H, W)``.
        - output: same shape; float dtypes kept, integer counts become float32.

    Example:
        >>> frames = torch.stack([torch.zeros(1, 2, 1, 1), torch.ones(1, 2, 1, 1)])
        >>> mixup_frames(frames, torch.tensor([1, 0]), torch.tensor([0.25, 0.25])).flatten().tolist()
        [0.75, 0.75, 0.25, 0.25]
    """
    out_dtype = batch.dtype if batch.dtype.is_floating_point else torch.float32
    work = torch.float64 if batch.dtype == torch.float64 else torch.float32
    w = weight.to(batch.device, work, non_blocking=True).view(-1, 1, 1, 1, 1)
    own = batch.to(work)
    other = own.index_select(0, partner.to(batch.device, non_blocking=True))
    return (other + w * (own - other)).to(out_dtype)


# --------------------------------------------------------------------------- events


def _in_box(x: Tensor, y: Tensor, owner: Tensor, box: Sequence[Tensor]) -> Tensor:
    """Per event whether ``(y, x)`` lies in the box of sample ``owner`` (per-event gathers)."""
    device = x.device
    top, left, height, width = (v.to(device, torch.int64, non_blocking=True).index_select(0, owner) for v in box)
    y64, x64 = y.to(torch.int64), x.to(torch.int64)
    return (y64 >= top) & (y64 < top + height) & (x64 >= left) & (x64 < left + width)


@register_kernel(cutout, EventBatch)
def cutout_events(batch: EventBatch, top: Tensor, left: Tensor, height: Tensor, width: Tensor) -> EventBatch:
    """Kernel of :func:`cutout` for an EventBatch: the events inside sample b's box removed.
    One host read (of the kept counts); binned, equal to :func:`cutout_frames`.

    Args:
        batch: the event streams.
        top, left, height, width: ``(B,)`` integer boxes.

    Shape:
        - batch: B streams, N events.
        - top, left, height, width: ``(B,)``.
        - output: B streams, at most N events (in their order).

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 0, 0, 1], [2, 1, 0, 1]])], sensor_size=(3, 4))
        >>> cutout_events(batch, *(torch.tensor([v]) for v in (1, 1, 2, 2))).x.tolist()
        [0]
    """
    if batch.num_events == 0:
        return batch
    sample = batch.sample_index().to(torch.int64)
    return _compact(batch, ~_in_box(batch.x, batch.y, sample, (top, left, height, width)))


def _with_partners(batch: EventBatch, partner: Tensor) -> tuple[EventBatch, Tensor, Tensor, Tensor]:
    """Each stream followed by a copy of its partner's stream, as one batch (the candidates),
    with, per candidate event, its stream (int64), whether it is the stream's own, and its
    position in the stream it was copied from. Index arithmetic on the device, sizes from the
    CPU offsets: sync-free, no loop over the streams. A copied event's time moves onto the
    stream's grid (``t + t_start[b] - t_start[partner[b]]``) when the batch has one."""
    device = batch.device
    lengths = torch.tensor(batch.lengths, dtype=torch.int64)
    starts = batch.offsets[:-1]
    own_len, part_len = lengths, lengths.index_select(0, partner)
    total = own_len + part_len
    offsets = torch.cat([torch.zeros(1, dtype=torch.int64), torch.cumsum(total, 0)])
    size = sum(total.tolist())  # host numbers (CPU offsets): no device read
    per_stream = torch.stack([own_len, starts, starts.index_select(0, partner), offsets[:-1]]).to(device, non_blocking=True)
    owner = torch.repeat_interleave(torch.arange(len(batch), device=device), total.to(device, non_blocking=True),
                                    output_size=size)
    own_n, own_start, part_start, first = per_stream.index_select(1, owner).unbind(0)
    local = torch.arange(size, device=device) - first
    own = local < own_n
    position = torch.where(own, local, local - own_n)
    source = torch.where(own, own_start, part_start) + position
    columns = {k: getattr(batch, k).index_select(0, source) for k in ("x", "y", "t", "p")}
    if batch.t_start is not None:
        shift = (batch.t_start - batch.t_start.index_select(0, partner)).to(device, batch.t.dtype, non_blocking=True)
        columns["t"] = torch.where(own, columns["t"], columns["t"] + shift.index_select(0, owner))
    merged = batch._replace(**columns, offsets=offsets, _sample=owner.to(torch.int32))
    return merged, owner, own, position


@register_kernel(cutmix, EventBatch)
def cutmix_events(
    batch: EventBatch, partner: Tensor, top: Tensor, left: Tensor, height: Tensor, width: Tensor
) -> EventBatch:
    """Kernel of :func:`cutmix` for an EventBatch: sample b keeps its events outside its box
    and takes sample ``partner[b]``'s events inside it (see the module docstring). One host
    read (of the kept counts); binned, equal to :func:`cutmix_frames`.

    Args:
        batch: the event streams.
        partner: ``(B,)`` indices of each stream's partner in the batch.
        top, left, height, width: ``(B,)`` integer boxes.

    Shape:
        - batch: B streams, N events.
        - partner, top, left, height, width: ``(B,)``.
        - output: B streams; stream b holds its own events outside its box, then its partner's inside.

    Example:
        >>> from event_transforms import EventBatch
        >>> a, b = torch.tensor([[0, 0, 0, 1], [1, 0, 0, 1]]), torch.tensor([[1, 0, 0, 0], [2, 0, 0, 0]])
        >>> batch = EventBatch.from_streams([a, b], sensor_size=(1, 3))
        >>> box = (torch.tensor([0, 0]), torch.tensor([1, 1]), torch.tensor([1, 1]), torch.tensor([1, 1]))
        >>> out = cutmix_events(batch, torch.tensor([1, 0]), *box)  # column 1 from the partner
        >>> out[0].x.tolist(), out[0].p.tolist()
        ([0, 1], [1, 0])
    """
    if batch.num_events == 0 or len(batch) == 0:
        return batch
    merged, owner, own, _ = _with_partners(batch, partner)
    inside = _in_box(merged.x, merged.y, owner, (top, left, height, width))
    itself = (partner == torch.arange(len(batch))).to(batch.device, non_blocking=True).index_select(0, owner)
    keep = torch.where(own, ~inside | itself, inside & ~itself)
    return _compact(merged, keep)


@register_kernel(mixup, EventBatch)
def mixup_events(batch: EventBatch, partner: Tensor, weight: Tensor, seed: Tensor) -> EventBatch:
    """Kernel of :func:`mixup` for an EventBatch: each event of sample b kept with probability
    ``weight[b]``, each event of sample ``partner[b]`` taken with probability
    ``1 - weight[b]`` (see the module docstring). Each event's uniform is a counter-based
    hash of sample b's ``seed`` and a counter, ``2·position + (0 for its own event, 1 for
    one of the partner's)`` (:mod:`~event_transforms.functional._random`): a sample's output depends only on its
    own events, its partner's and its seed. One host read (of the kept counts).

    Args:
        batch: the event streams.
        partner: ``(B,)`` indices of each stream's partner in the batch.
        weight: ``(B,)`` the stream's own share in [0, 1].
        seed: ``(B,)`` int64 per-sample seeds of the draws.

    Shape:
        - batch: B streams, N events.
        - partner, weight, seed: ``(B,)``.
        - output: B streams; stream b holds its kept own events, then those taken from its partner.

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 0, 0, 1]]), torch.tensor([[1, 0, 0, 0]])], sensor_size=(1, 2))
        >>> out = mixup_events(batch, torch.tensor([1, 0]), torch.tensor([1.0, 0.0]), torch.tensor([3, 4]))
        >>> out[0].x.tolist(), out[1].x.tolist()  # weight 1: itself; weight 0: its partner
        ([0], [0])
    """
    if batch.num_events == 0 or len(batch) == 0:
        return batch
    merged, owner, own, position = _with_partners(batch, partner)
    device = batch.device
    salt = sample_salts(seed, device).index_select(0, owner)
    u = uniform(salt, position * 2 + (~own).to(torch.int64), 1)  # own and copied events: distinct counters
    share = weight.to(device, torch.float64, non_blocking=True).index_select(0, owner)
    itself = (partner == torch.arange(len(batch))).to(device, non_blocking=True).index_select(0, owner)
    keep = torch.where(own, (u < share) | itself, (u < 1 - share) & ~itself)
    return _compact(merged, keep)


def mix_labels(labels: Tensor, partner: Scalars, weight: Scalars, *, num_classes: int | None = None) -> Tensor:
    """Mix targets as their frames were mixed: ``w · y_b + (1 - w) · y_partner[b]``.

    - Float targets of any shape ``(B, ...)`` are mixed as they are: regression targets
      such as force per frame ``(B, T)``, or soft/one-hot class targets ``(B, C)``. The
      dtype is kept.
    - Integer class indices ``(B,)`` need ``num_classes``: they become one-hot and then
      soft targets ``(B, num_classes)`` in float32 (what ``cross_entropy`` accepts).

    Args:
        labels: ``(B, ...)`` float targets or ``(B,)`` integer class indices.
        partner: ``(B,)`` sample indices, as given to the frames' kernel.
        weight: the sample's own share, a number or ``(B,)``.
        num_classes: number of classes, for integer labels.

    Shape:
        - labels: ``(B, ...)`` float, or ``(B,)`` integer.
        - partner: ``(B,)``; weight: a number or ``(B,)``.
        - output: float labels' shape and dtype; ``(B, num_classes)`` float32 for integer labels.

    Example:
        >>> mix_labels(torch.tensor([0, 2]), [1, 0], [0.75, 1.0], num_classes=3).tolist()
        [[0.75, 0.0, 0.25], [0.0, 0.0, 1.0]]
        >>> mix_labels(torch.tensor([[10.0, 20.0], [0.0, 0.0]]), [1, 0], 0.5).tolist()
        [[5.0, 10.0], [5.0, 10.0]]
    """
    if not isinstance(labels, Tensor):
        raise TypeError(f"labels must be a tensor of targets, got {type(labels).__name__}")
    if labels.dim() == 0:
        raise ValueError(f"labels must have a batch axis (B, ...), got {describe(labels)}")
    b = labels.shape[0]
    args = check_args("mix_labels", mix_labels_spec(b), b, partner=partner, weight=weight)
    return blend_labels(labels, args["partner"], args["weight"], check_classes(labels, num_classes))


