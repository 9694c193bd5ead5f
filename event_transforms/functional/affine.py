"""Affine warps: rotation, resize and ``affine`` through one warp.

:func:`rotate`, :func:`resize` and :func:`affine` (rotation, scale, translation and shear
in one 2×3 matrix) are special cases of one private warp, ``_affine``
(``affine(angle=a)`` equals ``rotate(a)``, ``affine(scale=s)`` equals ``resize(s)``), about
the event centroid (:func:`center_of_mass`) by default. It folds the T·2 frames of a
sequence into channels and calls ``affine_grid`` and ``grid_sample`` once with a (B, 2, 3)
matrix built on the host (the same sampling as kornia's ``warp_affine``, without its
float64 matrix helpers and at a quarter of its dispatched ops; see
``benchmarks/library/kornia_warp.py``), so one sampling grid serves every frame of a sequence (the
contact keeps its orientation), no (B·T) grids are built, and the device is never asked for
a number.

The warp core (centroid, sampling matrices, ``grid_sample``) lives in the private
``_warp`` module, which :mod:`.stretch`, :mod:`.perspective` and :mod:`.elastic` share.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torch import Tensor

from .._params import Param, check_args
from .._validation import INTERPOLATIONS, check_choice, describe, on_host
from ..events.batch import EventBatch
from ._dispatch import batch_of, call_kernel, register_kernel
from ._event_ops import _round_to
from ._frame_ops import _output_dtype, _work_dtype
from ._warp import Center, check_center, _mass_moments, _sampling_matrices, _theta_on_device, _warp, center_of_mass

__all__ = [
    "center_of_mass",
    "event_centroid",
    "rotate", "rotate_frames", "rotate_events",
    "resize", "resize_frames", "resize_events",
    "affine", "affine_frames", "affine_events",
]

Scalars = float | Sequence[float] | Tensor
Pairs = Sequence[float] | Tensor


# --------------------------------------------------------------------------- declarations
# Each operation's per-sample arguments, declared once: the dispatcher checks its arguments
# against it (check_args), the module's params_spec returns it (check_tree).


#: :func:`rotate`: degrees, counter-clockwise.
ROTATE_SPEC = {"angle": Param("float")}
#: :func:`resize`: a zoom factor > 0.
RESIZE_SPEC = {"scale": Param("float", low=0.0, low_open=True)}
#: :func:`affine`: rotation, zoom, translation (dy, dx) and shear (x, y) in (-90, 90) degrees.
AFFINE_SPEC = {
    **ROTATE_SPEC, **RESIZE_SPEC, "translate": Param("float", shape=(2,)),
    "shear": Param("float", shape=(2,), low=-90.0, high=90.0, low_open=True, high_open=True),
}


def _affine(
    batch: Tensor,
    angle: Tensor | None,
    scale: Tensor | None,
    center: Center,
    mode: str,
    *,
    shear: Tensor | None = None,
    translate: Tensor | None = None,
) -> Tensor:
    """Rotate by ``angle`` degrees and zoom by ``scale`` about ``center``, per sample (and,
    for :func:`~event_transforms.functional.affine`, shear and translate: rotate and resize
    are its special cases, through this one function).

    ``angle`` and ``scale`` are (B,) float64 CPU tensors (``None``: 0° and 1), ``shear``
    (B, 2) (x, y) degrees and ``translate`` (B, 2) (dy, dx) pixels (``None``: none). The
    forward map of sample b is ``dst = s R(θ) Sh (src - c) + c + t`` (OpenCV's and kornia's
    convention). The sampling matrix
    (its inverse, in the normalised coordinates of ``grid_sample`` with
    ``align_corners=True``) is built on the host in float64 from the parameters; only the
    centroid, when ``center="mass"``, comes from the device, and enters through one batched
    matrix product. Then one ``affine_grid`` and one ``grid_sample`` serve all T·2 frames of
    a sequence, folded into channels: about 25 device ops and no host synchronisation.
    """
    b, t, p, height, width = batch.shape
    out_dtype = _output_dtype(batch.dtype, mode)
    if batch.numel() == 0:
        return batch.to(out_dtype, copy=True)
    work = _work_dtype(batch.dtype, mode)
    extra = shear is not None or translate is not None
    if extra:  # host-drawn by make_params; a device tensor here is read once
        shear = None if shear is None else shear.detach().to("cpu", torch.float64)
        translate = None if translate is None else translate.detach().to("cpu", torch.float64)
    if not extra and not on_host(angle, scale):
        theta = _theta_on_device(batch, angle, scale, center).to(work)
    elif isinstance(center, str) and center == "mass":
        angle_np = np.zeros(b) if angle is None else np.array(angle.tolist(), dtype=np.float64)
        scale_np = np.ones(b) if scale is None else np.array(scale.tolist(), dtype=np.float64)
        matrix = _sampling_matrices(angle_np, scale_np, height, width, shear=shear, translate=translate)
        moments = _mass_moments(batch)  # (B, 3): [M, M y, M x] on the device
        theta = torch.bmm(torch.from_numpy(matrix).to(batch.device), moments.unsqueeze(2)) / moments[:, :1, None]
        theta = theta.view(b, 2, 3).to(work)
    else:
        angle_np = np.zeros(b) if angle is None else np.array(angle.tolist(), dtype=np.float64)
        scale_np = np.ones(b) if scale is None else np.array(scale.tolist(), dtype=np.float64)
        matrix = _sampling_matrices(angle_np, scale_np, height, width, shear=shear, translate=translate)
        if isinstance(center, str):  # "image"
            yx = np.array([(height - 1) / 2, (width - 1) / 2])
        else:
            yx = torch.as_tensor(center, dtype=torch.float64).cpu().numpy()
        ones_yx = np.concatenate([np.ones((b, 1)), np.broadcast_to(yx, (b, 2))], axis=1)
        theta = torch.from_numpy((matrix @ ones_yx[:, :, None]).reshape(b, 2, 3)).to(batch.device, work)
    return _warp(batch, theta, mode)


def rotate(
    inputs: Tensor | EventBatch, angle: Scalars, *, center: Center = "mass", mode: str = "bilinear"
) -> Tensor | EventBatch:
    """Rotate every frame of each sequence by the sequence's angle about its centre.

    Positive angles turn counter-clockwise on the displayed image (row 0 at the top), as
    in torchvision and kornia. Pixels that come from outside the frame are zero. On an
    :class:`~event_transforms.EventBatch` each event moves to the nearest pixel
    (:func:`rotate_events`: counts are conserved, ``mode`` does not apply).

    Args:
        inputs: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch.
        angle: degrees, a number or one per sample ``(B,)``.
        center: ``"mass"`` (event centroid of the whole sequence, image centre when
            empty), ``"image"``, a ``(y, x)`` pair, or a ``(B, 2)`` tensor of pairs.
        mode: ``"bilinear"`` (counts are interpolated, totals change slightly) or
            ``"nearest"``.

    Returns:
        The rotated frames, same shape and device. ``bilinear`` returns the input dtype
        for float input and float32 for integer input; ``nearest`` keeps the dtype.

    Shape:
        ``(T, 2, H, W)`` -> ``(T, 2, H, W)``; ``(B, T, 2, H, W)`` -> same.

    Example:
        >>> frames = torch.zeros(1, 2, 5, 5, dtype=torch.int16)
        >>> frames[0, 1, 2, 4] = 7  # right of the centre
        >>> out = rotate(frames, 90.0, center="image", mode="nearest")
        >>> out.dtype, out[0, 1].nonzero().tolist(), int(out.sum())
        (torch.int16, [[0, 2]], 7)
    """
    batch, b, restore = batch_of(inputs)
    center = check_center(center, b)
    angle_t = check_args("rotate", ROTATE_SPEC, b, angle=angle)["angle"]
    return restore(call_kernel(rotate, batch, angle_t, center=center, mode=check_choice(mode, "mode", INTERPOLATIONS)))


def resize(
    inputs: Tensor | EventBatch, scale: Scalars, *, center: Center = "mass", mode: str = "bilinear"
) -> Tensor | EventBatch:
    """Zoom each sequence by ``scale`` about its centre, keeping H×W (zero margin).

    ``scale`` is the paper's β = target object size / source object size: 1.25 makes a
    12 mm object's contact look like a 15 mm object's, 0.83 shrinks an 18 mm one. With
    bilinear sampling the total count scales by about β² as in image resizing; shrinking
    samples the source without anti-aliasing, as the paper's linear resize does. On an
    EventBatch each event moves to the nearest pixel (:func:`resize_events`).

    Args:
        inputs: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch.
        scale: zoom factor > 0, a number or one per sample ``(B,)``.
        center: ``"mass"``, ``"image"``, ``(y, x)`` or a ``(B, 2)`` tensor (see :func:`rotate`).
        mode: ``"bilinear"`` or ``"nearest"``.

    Returns:
        The resized frames, same shape and device; dtype as in :func:`rotate`.

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: same shape and device; float input keeps its dtype, integer input gives float32
          (``mode="nearest"`` keeps it).
        - scale: a number or ``(B,)``.

    Example:
        >>> frames = torch.zeros(1, 2, 5, 5)
        >>> frames[0, 0, 2, 3] = 1.0  # one pixel right of the centre
        >>> resize(frames, 2.0, center="image")[0, 0, 2].tolist()
        [0.0, 0.0, 0.0, 0.5, 1.0]
    """
    batch, b, restore = batch_of(inputs)
    center = check_center(center, b)
    scale_t = check_args("resize", RESIZE_SPEC, b, scale=scale)["scale"]
    return restore(call_kernel(resize, batch, scale_t, center=center, mode=check_choice(mode, "mode", INTERPOLATIONS)))


def affine(
    inputs: Tensor | EventBatch,
    *,
    angle: Scalars = 0.0,
    translate: Pairs = (0.0, 0.0),
    scale: Scalars = 1.0,
    shear: Pairs = (0.0, 0.0),
    center: Center = "mass",
    mode: str = "bilinear",
) -> Tensor | EventBatch:
    """Rotate, scale, shear and translate every frame of each sequence with one warp.

    The forward map of sample b is ``dst = s·R(θ)·Sh_x·Sh_y·(src - c) + c + t`` (OpenCV's
    and kornia's convention, the same as :func:`~event_transforms.functional.rotate` and
    :func:`~event_transforms.functional.resize`, which it generalises). Pixels that come
    from outside the frame are zero. On an EventBatch (:func:`affine_events`) each event
    moves to the nearest pixel; shear is not supported there (``ValueError`` if non-zero).

    Args:
        inputs: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch.
        angle: degrees, counter-clockwise on the displayed image; a number or ``(B,)``.
        translate: ``(dy, dx)`` in pixels (down, right), or a ``(B, 2)`` tensor.
        scale: zoom factor > 0, a number or ``(B,)``.
        shear: ``(x, y)`` shear angles in degrees (each in (-90, 90)), or ``(B, 2)``.
        center: ``"mass"``, ``"image"``, ``(y, x)`` or a ``(B, 2)`` tensor (see :func:`rotate`).
        mode: ``"bilinear"`` or ``"nearest"``.

    Returns:
        The warped frames, same shape and device; dtype as in :func:`rotate`.

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: same shape and device; float input keeps its dtype, integer input gives float32
          (``mode="nearest"`` keeps it).
        - angle, scale: a number or ``(B,)``; translate, shear: a pair or ``(B, 2)``.

    Example:
        >>> frames = torch.zeros(1, 2, 5, 5, dtype=torch.int16)
        >>> frames[0, 1, 2, 2] = 3
        >>> out = affine(frames, translate=(1, -2), center="image", mode="nearest")
        >>> out.dtype, out[0, 1].nonzero().tolist()
        (torch.int16, [[3, 0]])
    """
    batch, b, restore = batch_of(inputs)
    args = check_args("affine", AFFINE_SPEC, b, angle=angle, scale=scale, translate=translate, shear=shear)
    check_choice(mode, "mode", INTERPOLATIONS)
    center = check_center(center, b)
    return restore(call_kernel(
        affine, batch, args["angle"], args["scale"], shear=args["shear"], translate=args["translate"], center=center, mode=mode
    ))


@register_kernel(rotate, Tensor)
def rotate_frames(frames: Tensor, angle: Tensor, *, center: Center = "mass", mode: str = "bilinear") -> Tensor:
    """Kernel of :func:`rotate` for frames ``(B, T, 2, H, W)``, ``angle`` (B,) float64 CPU degrees.

    Args:
        frames: event counts ``(B, T, 2, H, W)`` (the dispatcher adds the batch dimension).
        angle: degrees, a number or one per sample ``(B,)``.
        center: ``"mass"`` (event centroid of the whole sequence, image centre when
            empty), ``"image"``, a ``(y, x)`` pair, or a ``(B, 2)`` tensor of pairs.
        mode: ``"bilinear"`` (counts are interpolated, totals change slightly) or
            ``"nearest"``.

    Shape:
        - frames: ``(B, T, 2, H, W)``; per-sample arguments ``(B,)`` (or ``(B, 2)``).
        - output: as :func:`rotate` gives for a batch.
    """
    return _affine(frames, angle, None, center, mode)


@register_kernel(resize, Tensor)
def resize_frames(frames: Tensor, scale: Tensor, *, center: Center = "mass", mode: str = "bilinear") -> Tensor:
    """Kernel of :func:`resize` for frames ``(B, T, 2, H, W)``, ``scale`` (B,) float64 CPU.

    Args:
        frames: event counts ``(B, T, 2, H, W)`` (the dispatcher adds the batch dimension).
        scale: zoom factor > 0, a number or one per sample ``(B,)``.
        center: ``"mass"``, ``"image"``, ``(y, x)`` or a ``(B, 2)`` tensor (see :func:`rotate`).
        mode: ``"bilinear"`` or ``"nearest"``.

    Shape:
        - frames: ``(B, T, 2, H, W)``; per-sample arguments ``(B,)`` (or ``(B, 2)``).
        - output: as :func:`resize` gives for a batch.
    """
    return _affine(frames, None, scale, center, mode)


@register_kernel(affine, Tensor)
def affine_frames(
    frames: Tensor,
    angle: Tensor,
    scale: Tensor,
    *,
    shear: Tensor | None = None,
    translate: Tensor | None = None,
    center: Center = "mass",
    mode: str = "bilinear",
) -> Tensor:
    """Kernel of :func:`affine` for frames ``(B, T, 2, H, W)`` and per-sample CPU parameters.

    Args:
        frames: event counts ``(B, T, 2, H, W)`` (the dispatcher adds the batch dimension).
        angle: degrees, counter-clockwise on the displayed image; a number or ``(B,)``.
        scale: zoom factor > 0, a number or ``(B,)``.
        shear: ``(x, y)`` shear angles in degrees (each in (-90, 90)), or ``(B, 2)``.
        translate: ``(dy, dx)`` in pixels (down, right), or a ``(B, 2)`` tensor.
        center: ``"mass"``, ``"image"``, ``(y, x)`` or a ``(B, 2)`` tensor (see :func:`rotate`).
        mode: ``"bilinear"`` or ``"nearest"``.

    Shape:
        - frames: ``(B, T, 2, H, W)``; per-sample arguments ``(B,)`` (or ``(B, 2)``).
        - output: as :func:`affine` gives for a batch.
    """
    return _affine(frames, angle, scale, center, mode, shear=shear, translate=translate)


# --------------------------------------------------------------------------- events


def event_centroid(batch: EventBatch) -> Tensor:
    """(B, 2) float64 ``(y, x)`` mean event position per stream on the batch's device; an
    empty stream gets the image centre ``((H - 1) / 2, (W - 1) / 2)``. Sync-free.

    Args:
        batch: the event streams.

    Shape:
        - batch: B streams, N events.
        - output: ``(B, 2)`` float64 ``(y, x)`` on the batch's device.

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 1, 100, 1], [2, 0, 15_000, 0]]),
        ...                                  torch.tensor([[1, 1, 50, 0]])], sensor_size=(2, 3),
        ...                                  frame_ms=10.0, t_start=0, n_frames=2)
        >>> event_centroid(batch).tolist()
        [[0.5, 1.0], [1.0, 1.0]]
    """
    height, width = batch.sensor_size
    lengths = torch.tensor(batch.lengths, dtype=torch.int64)
    device = batch.device
    if batch.num_events == 0 or len(batch) == 0:
        return torch.tensor([[(height - 1) / 2, (width - 1) / 2]], dtype=torch.float64, device=device).expand(len(batch), 2)
    on_device = lengths.to(device, non_blocking=True)
    if device.type == "cpu":  # slice sums: no per-event index, no float64 copy of the columns
        bounds = batch.offsets.tolist()
        sums = torch.stack([torch.stack([batch.y[lo:hi].sum(dtype=torch.float64), batch.x[lo:hi].sum(dtype=torch.float64)])
                            for lo, hi in zip(bounds, bounds[1:])])
    else:
        sample = batch.sample_index()
        sums = torch.zeros(len(batch), 2, dtype=torch.float64, device=device)
        sums[:, 0].index_add_(0, sample, batch.y.to(torch.float64))
        sums[:, 1].index_add_(0, sample, batch.x.to(torch.float64))
    image = torch.tensor([(height - 1) / 2, (width - 1) / 2], dtype=torch.float64, device=device)
    count = on_device.to(torch.float64).unsqueeze(1)
    return torch.where(count > 0, sums / count.clamp_min(1), image)


def _affine_events(
    batch: EventBatch,
    *,
    angle: Tensor | None = None,
    scale: Tensor | None = None,
    center: str | Sequence[float] | Tensor = "mass",
) -> EventBatch:
    """Rotate by ``angle`` (degrees, counter-clockwise as in :func:`~event_transforms.functional.rotate`)
    and scale by ``scale`` about the centre, per sample; each event moves to the nearest pixel.

    The map is the frame kernel's forward map: ``(x', y') = c + s R (x - c, y - c)`` with
    ``R = [[cos, sin], [-sin, cos]]`` in (x, y) order (y down), ``c`` the event centroid
    of the stream (``center="mass"``, float64, all events), the image centre
    (``"image"``) or a given ``(y, x)``. Count-conserving (a bilinear frame warp spreads
    counts instead). Sync-free: a handful of per-event ops whatever B.
    """
    b = len(batch)
    radians = np.deg2rad(np.asarray(angle.tolist() if angle is not None else [0.0] * b, dtype=np.float64))
    s = np.asarray(scale.tolist() if scale is not None else [1.0] * b, dtype=np.float64)
    cos, sin = np.cos(radians) * s, np.sin(radians) * s
    height, width = batch.sensor_size
    device = batch.device
    if center == "mass":
        c = event_centroid(batch)
    elif center == "image":
        c = torch.tensor([[(height - 1) / 2, (width - 1) / 2]], dtype=torch.float64, device=device).expand(b, 2)
    else:
        c = torch.as_tensor(center, dtype=torch.float64).to(device).reshape(-1, 2).expand(b, 2)
    if batch.num_events == 0:
        return batch
    linear = torch.from_numpy(np.stack([cos, sin, -sin, cos], 1)).to(device)  # (B, 4): x' row, y' row
    cy, cx = c[:, 0], c[:, 1]
    # x' = a x + b y + e,  y' = c x + d y + f  with e, f folding the centre in
    e = cx - linear[:, 0] * cx - linear[:, 1] * cy
    f = cy - linear[:, 2] * cx - linear[:, 3] * cy
    coefficients = torch.cat([linear, e.unsqueeze(1), f.unsqueeze(1)], 1).to(torch.float32).t().contiguous()
    x, y = batch.x.to(torch.float32), batch.y.to(torch.float32)
    if device.type == "cpu":
        # per-sample slices with the sample's six numbers: no per-event gathers (on the CPU
        # the coefficients are host memory; float32 arithmetic as on accelerators, which may
        # round the last bit differently)
        new_x, new_y = torch.empty_like(x), torch.empty_like(y)
        bounds = batch.offsets.tolist()
        for i, (a, bb, cc, d, ee, ff) in enumerate(coefficients.t().tolist()):
            lo, hi = bounds[i], bounds[i + 1]
            if hi > lo:
                xs, ys = x[lo:hi], y[lo:hi]
                torch.mul(xs, a, out=new_x[lo:hi]).add_(ee).add_(ys, alpha=bb)
                torch.mul(xs, cc, out=new_y[lo:hi]).add_(ff).add_(ys, alpha=d)
    else:  # accelerators: six gathers and four fused ops for the whole batch, whatever B
        sample = batch.sample_index()
        a, bb, cc, d, ee, ff = (coefficients[i].index_select(0, sample) for i in range(6))
        new_x = torch.addcmul(torch.addcmul(ee, a, x), bb, y)
        new_y = torch.addcmul(torch.addcmul(ff, cc, x), d, y)
    return batch._replace(x=_round_to(new_x, torch.int16), y=_round_to(new_y, torch.int16))


@register_kernel(rotate, EventBatch)
def rotate_events(batch: EventBatch, angle: Tensor, *, center: Center = "mass", mode: str = "bilinear") -> EventBatch:
    """Kernel of :func:`rotate` for an EventBatch: each event to the nearest pixel (``mode`` does
    not apply).

    Args:
        batch: the event streams.
        angle: ``(B,)`` degrees, counter-clockwise.
        center: ``"mass"`` (each stream's event centroid), ``"image"`` or ``(y, x)``.
        mode: kept for the dispatcher's signature; events move to the nearest pixel.

    Shape:
        - batch: B streams, N events.
        - angle: ``(B,)``.
        - output: the same streams and events, each at its nearest pixel.

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[4, 2, 0, 1]])], sensor_size=(5, 5))
        >>> out = rotate_events(batch, torch.tensor([90.0]), center="image")
        >>> out.x.tolist(), out.y.tolist()
        ([2], [0])
    """
    return _affine_events(batch, angle=angle, center=_event_center(center))


@register_kernel(resize, EventBatch)
def resize_events(batch: EventBatch, scale: Tensor, *, center: Center = "mass", mode: str = "bilinear") -> EventBatch:
    """Kernel of :func:`resize` for an EventBatch: each event to the nearest pixel.

    Args:
        batch: the event streams.
        scale: ``(B,)`` zoom factors > 0.
        center: ``"mass"`` (each stream's event centroid), ``"image"`` or ``(y, x)``.
        mode: kept for the dispatcher's signature; events move to the nearest pixel.

    Shape:
        - batch: B streams, N events.
        - scale: ``(B,)``.
        - output: the same streams and events, each at its nearest pixel.

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[3, 2, 0, 1]])], sensor_size=(5, 5))
        >>> zoomed = resize_events(batch, torch.tensor([2.0]), center="image")
        >>> zoomed.x.tolist(), zoomed.y.tolist()  # (x, y) = (3, 2) -> 2 + 2 (3 - 2), 2
        ([4], [2])
    """
    return _affine_events(batch, scale=scale, center=_event_center(center))


@register_kernel(affine, EventBatch)
def affine_events(
    batch: EventBatch,
    angle: Tensor,
    scale: Tensor,
    *,
    shear: Tensor | None = None,
    translate: Tensor | None = None,
    center: Center = "mass",
    mode: str = "bilinear",
) -> EventBatch:
    """Kernel of :func:`affine` for an EventBatch: rotation and scale as :func:`rotate_events`,
    then ``translate`` rounded to whole pixels; a non-zero ``shear`` is refused.

    Args:
        batch: the event streams.
        angle: ``(B,)`` degrees, counter-clockwise.
        scale: ``(B,)`` zoom factors > 0.
        shear: must be ``None`` or zero: shear is not supported on events.
        translate: ``(B, 2)`` ``(dy, dx)`` pixels, or ``None``.
        center: ``"mass"`` (each stream's event centroid), ``"image"`` or ``(y, x)``.
        mode: kept for the dispatcher's signature; events move to the nearest pixel.

    Shape:
        - batch: B streams, N events.
        - angle, scale: ``(B,)``; translate: ``(B, 2)``.
        - output: the same streams and events, each at its nearest pixel.

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[2, 1, 0, 1]])], sensor_size=(3, 3))
        >>> turned = affine_events(batch, torch.tensor([90.0]), torch.tensor([1.0]), center="image")
        >>> turned.y.tolist(), turned.x.tolist()  # (y, x) = (1, 2) -> (0, 1) about (1, 1)
        ([0], [1])
    """
    if shear is not None and any(v != 0 for v in shear.flatten().tolist()):  # CPU params: no sync
        raise ValueError(f"affine: shear is not supported on events, got {describe(shear)}")
    out = _affine_events(batch, angle=angle, scale=scale, center=_event_center(center))
    if translate is not None and any(v != 0 for v in translate.flatten().tolist()):
        from .geometry import translate_events

        out = translate_events(out, translate.round().to(torch.int64))
    return out


def _event_center(center: Center) -> Center:
    return center if isinstance(center, (str, Tensor)) else tuple(float(c) for c in center)
