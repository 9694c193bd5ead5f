"""Elastic warps: a smoothed random displacement field per sequence.

:func:`elastic` folds the T·2 frames of a sequence into channels and samples them at one grid
per sequence built from a Gaussian-smoothed displacement field (what kornia's
``elastic_transform2d`` computes, with a fraction of its dispatched ops). On an EventBatch each
event follows the field.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch
from torch import Tensor

from .._params import Param, check_args
from .._validation import INTERPOLATIONS, as_number, check_choice, describe
from ..events.batch import EventBatch
from ._dispatch import batch_of, kernel_for, register_kernel
from ._frame_ops import _output_dtype, _work_dtype
from ._warp import _base_grid, _bilinear, _keep_on_sensor, _normalisation, _sample

__all__ = ["elastic", "elastic_frames", "elastic_events"]

Scalars = float | Sequence[float] | Tensor


def elastic_spec(shape: Sequence[int]) -> dict[str, Param]:
    """:func:`elastic`'s per-sample arguments for a batch ``shape`` (B, T, 2, H, W): the
    strength ``alpha`` >= 0 and the displacement noise in [-1, 1]."""
    return {"alpha": Param("float", low=0.0), "noise": Param("float", shape=(2, *shape[-2:]), low=-1.0, high=1.0)}


def _gaussian_kernel(sigma: float, device: torch.device, dtype: torch.dtype) -> Tensor:
    """A normalised 1-D Gaussian of ``sigma`` pixels over ±3 sigma (odd length)."""
    radius = math.ceil(3 * sigma)
    offsets = np.arange(-radius, radius + 1, dtype=np.float64)
    weights = np.exp(-0.5 * (offsets / sigma) ** 2)
    return torch.from_numpy(weights / weights.sum()).to(device, dtype, non_blocking=True)


def _smoothed(noise: Tensor, sigma: float, device: torch.device, dtype: torch.dtype) -> Tensor:
    """(B·2, 1, H, W): each channel of (B, 2, H, W) ``noise`` smoothed by two 1-D Gaussian
    passes of ``sigma`` pixels (zero outside the frame)."""
    b, _, height, width = noise.shape
    kernel = _gaussian_kernel(sigma, device, dtype)
    radius = kernel.shape[0] // 2
    field = noise.to(device, dtype, non_blocking=True).reshape(b * 2, 1, height, width)
    field = torch.nn.functional.conv2d(field, kernel.view(1, 1, -1, 1), padding=(radius, 0))
    return torch.nn.functional.conv2d(field, kernel.view(1, 1, 1, -1), padding=(0, radius))


def elastic_frames(batch: Tensor, noise: Tensor, alpha: Tensor, sigma: float, mode: str) -> Tensor:
    """:func:`elastic` on a (B, T, 2, H, W) batch with checked (B, 2, H, W) ``noise`` and (B,)
    float64 CPU ``alpha`` (pixels): two 1-D Gaussian passes (zero outside the frame) smooth the
    noise, and the field, in normalised units, moves the identity grid.

    Args:
        batch: event counts ``(B, T, 2, H, W)`` (the dispatcher adds the batch dimension).
        noise: raw displacements in [-1, 1], ``(2, H, W)`` or ``(B, 2, H, W)``, channel 0
            along y (down), channel 1 along x (right); e.g. ``2 * torch.rand(B, 2, H, W) - 1``.
        alpha: strength in pixels (>= 0), a number or ``(B,)``.
        sigma: smoothness of the field in pixels (> 0).
        mode: ``"bilinear"`` or ``"nearest"``.

    Shape:
        - frames: ``(B, T, 2, H, W)``; per-sample arguments ``(B,)`` (or ``(B, 2)``).
        - output: as :func:`elastic` gives for a batch.
    """
    b, _, _, height, width = batch.shape
    out_dtype = _output_dtype(batch.dtype, mode)
    if batch.numel() == 0:
        return batch.to(out_dtype, copy=True)
    work = _work_dtype(batch.dtype, mode)
    field = _smoothed(noise, sigma, batch.device, work)
    norm = _normalisation(height, width)
    units = torch.from_numpy(alpha.numpy()[:, None] * np.array([norm[1, 1], norm[0, 0]]))  # (B, 2) as (y, x)
    field = field.view(b, 2, height, width) * units.to(batch.device, work, non_blocking=True).view(b, 2, 1, 1)
    grid = _base_grid(height, width, batch.device, work) + field.permute(0, 2, 3, 1).flip(-1)  # (x, y) last
    return _sample(batch, grid, mode, work, out_dtype)


def elastic(
    frames: Tensor | EventBatch,
    noise: Tensor,
    *,
    alpha: Scalars = 50.0,
    sigma: float = 5.0,
    mode: str = "bilinear",
) -> Tensor | EventBatch:
    """Displace the pixels of every frame of each sequence by one smooth random field per sequence.

    The elastic distortion of Simard et al. (2003), as torchvision's ``ElasticTransform``:
    the field is ``alpha`` times ``noise`` smoothed by a Gaussian of ``sigma`` pixels (zero
    outside the frame); output pixel (y, x) samples the input at (y, x) + field(y, x). All
    T·2 frames of a sequence share the field (the surface deforms, the contact keeps its
    shape over time) and are sampled at one grid (kornia's ``elastic_transform2d`` with
    its ``alpha`` in pixels gives the same result, frame by frame). Pixels that come from
    outside the frame are zero.

    On an EventBatch (:func:`elastic_events`) each event moves the other way: from p to the
    q with ``q + field(q) = p`` (the frame map inverted, by a few fixed-point steps
    ``q <- p - field(q)`` on the bilinearly interpolated field), to the nearest pixel.
    Counts are kept (``mode`` does not apply); events warped off the sensor are dropped,
    with the :class:`~event_transforms.events.EventsOutsideSensorWarning` binning gives.

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch.
        noise: raw displacements in [-1, 1], ``(2, H, W)`` or ``(B, 2, H, W)``, channel 0
            along y (down), channel 1 along x (right); e.g. ``2 * torch.rand(B, 2, H, W) - 1``.
        alpha: strength in pixels (>= 0), a number or ``(B,)``.
        sigma: smoothness of the field in pixels (> 0).
        mode: ``"bilinear"`` or ``"nearest"``.

    Returns:
        The warped frames, same shape and device; dtype as in :func:`rotate`.

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: same shape and device; float input keeps its dtype, integer input gives float32
          (``mode="nearest"`` keeps it).
        - noise: ``(2, H, W)`` or ``(B, 2, H, W)``; alpha: a number or ``(B,)``.

    Example:
        >>> frames = torch.zeros(1, 2, 9, 9)
        >>> frames[0, 1, 4, 4] = 1.0
        >>> noise = torch.zeros(2, 9, 9)
        >>> noise[1] = 1.0  # sample from the right everywhere: content moves left
        >>> out = elastic(frames, noise, alpha=2.0, sigma=1.0, mode="nearest")
        >>> out[0, 1].nonzero().tolist()
        [[4, 2]]
    """
    kernel = kernel_for(elastic, frames)
    batch, b, unbatch = batch_of(frames)
    height, width = batch.sensor_size if isinstance(batch, EventBatch) else batch.shape[-2:]
    if not isinstance(noise, Tensor):
        raise TypeError(f"noise must be a tensor (2, H, W) or (B, 2, H, W), got {type(noise).__name__}")
    if tuple(noise.shape) == (2, height, width):
        noise = noise.expand(b, 2, height, width)
    if tuple(noise.shape) != (b, 2, height, width) or not noise.is_floating_point():
        raise ValueError(
            f"noise must be a float tensor (2, {height}, {width}) or ({b}, 2, {height}, {width}), "
            f"got {describe(noise)} of dtype {noise.dtype}"
        )
    alpha_t = check_args("elastic", elastic_spec((height, width)), b, alpha=alpha)["alpha"]
    sigma = as_number(sigma, "sigma")
    if not 0 < sigma < math.inf:
        raise ValueError(f"sigma must be finite and > 0, got {sigma!r}")
    check_choice(mode, "mode", INTERPOLATIONS)
    return unbatch(kernel(batch, noise, alpha_t, sigma, mode))


#: Fixed-point steps of :func:`elastic_events` (each costs one bilinear gather of the field).
ELASTIC_STEPS = 4


@register_kernel(elastic, EventBatch)
def elastic_events(batch: EventBatch, noise: Tensor, alpha: Tensor, sigma: float, mode: str = "bilinear") -> EventBatch:
    """Kernel of :func:`elastic` for an EventBatch: the field of the frame kernel, in pixels
    (``alpha[b]`` times the smoothed ``noise[b]``), is inverted per event by
    ``ELASTIC_STEPS`` fixed-point steps ``q <- p - field(q)`` from ``q = p`` (the field read
    bilinearly, clamped at the border), then rounded to the nearest pixel. The steps converge
    where the field's slope is below 1 (a smooth field: ``alpha`` small against ``sigma``);
    a field that folds the image has no inverse and the last step is used. Events off the
    sensor are dropped with a warning. No loop over the samples; host reads: the dropped
    and kept counts.

    Args:
        batch: the event streams.
        noise: ``(B, 2, H, W)`` raw displacements in [-1, 1] on the batch's sensor.
        alpha: ``(B,)`` strengths in pixels (>= 0).
        sigma: smoothness of the field in pixels (> 0).
        mode: not used (each event lands in one pixel).

    Shape:
        - batch: B streams, N events on an ``(H, W)`` sensor.
        - noise: ``(B, 2, H, W)``; alpha: ``(B,)``.
        - output: B streams, at most N events (those on the sensor, in their order).

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[4, 4, 0, 1]])], sensor_size=(9, 9))
        >>> noise = torch.zeros(1, 2, 9, 9)
        >>> noise[0, 1] = 1.0  # frames sample from the right: content moves left
        >>> elastic_events(batch, noise, torch.tensor([2.0]), 1.0).x.tolist()
        [2]
    """
    b = len(batch)
    if batch.num_events == 0 or b == 0:
        return batch
    height, width = batch.sensor_size
    device, f64 = batch.device, torch.float64
    field = _smoothed(noise, sigma, device, f64).view(b, 2, height * width)
    field = (field * alpha.to(device, f64, non_blocking=True).view(b, 1, 1)).reshape(-1)  # pixels, (y, x) channels
    sample = batch.sample_index().to(torch.int64)
    base_y = sample * (2 * height * width)
    base_x = base_y + height * width
    px, py = batch.x.to(f64), batch.y.to(f64)
    qx, qy = px, py
    for _ in range(ELASTIC_STEPS):
        dy, dx = _bilinear(field, (base_y, base_x), qy, qx, height, width)
        qx, qy = px - dx, py - dy
    return _keep_on_sensor(batch, qx, qy)


register_kernel(elastic, Tensor)(elastic_frames)
