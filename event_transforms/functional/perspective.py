"""Perspective warps: where the frame's four corners go, one homography per sequence.

:func:`perspective` is a warp the affine matrix cannot express: it folds the T·2 frames of a
sequence into channels and samples them at one grid per sequence built from a host
homography (what kornia's ``warp_perspective`` computes, with a fraction of its dispatched
ops). On an EventBatch each event moves to its pixel under the homography.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torch import Tensor

from .._params import Param, check_args
from .._validation import INTERPOLATIONS, check_choice
from ..events.batch import EventBatch
from ._dispatch import batch_of, kernel_for, register_kernel
from ._frame_ops import _output_dtype, _work_dtype
from ._warp import _base_grid, image_corners, _keep_on_sensor, _normalisation, _sample

__all__ = ["perspective", "perspective_frames", "perspective_events"]


def _convex(corners: Tensor) -> str | None:
    """Whether (B, 4, 2) (y, x) corners make convex quadrilaterals in the frame's corner order."""
    edges = corners.roll(-1, dims=1) - corners  # (B, 4, 2) as (dy, dx)
    after = edges.roll(-1, dims=1)
    turns = edges[..., 1] * after[..., 0] - edges[..., 0] * after[..., 1]
    if bool((turns > 0).all()):
        return None
    return ("make a convex quadrilateral in the order top-left, top-right, bottom-right, bottom-left "
            "(as the frame's corners do)")


#: :func:`perspective`: where the frame's four corners go, (y, x), a convex quadrilateral.
PERSPECTIVE_SPEC = {"corners": Param("float", shape=(4, 2), rule=_convex)}


def _perspective_matrices(corners: Tensor, height: int, width: int) -> np.ndarray:
    """(B, 3, 3) float64 host matrices taking an output grid point (u, v, 1) to its source
    point in homogeneous normalised coordinates: the homography from ``corners`` back to the
    frame's corners (four point pairs, eight unknowns, one solve per sample), conjugated by
    the normalisation. NumPy, not torch: host numbers, no dispatch."""
    target = np.asarray(corners.tolist(), dtype=np.float64)[..., ::-1]  # (B, 4, 2) as (x, y): output
    source = image_corners(height, width).numpy()[:, ::-1]  # (4, 2) as (x, y): input
    b = target.shape[0]
    u, v = target[..., 0], target[..., 1]  # (B, 4)
    x, y = np.broadcast_to(source[:, 0], (b, 4)), np.broadcast_to(source[:, 1], (b, 4))
    zeros, ones = np.zeros((b, 4)), np.ones((b, 4))
    rows_x = np.stack([u, v, ones, zeros, zeros, zeros, -u * x, -v * x], -1)
    rows_y = np.stack([zeros, zeros, zeros, u, v, ones, -u * y, -v * y], -1)
    system = np.concatenate([rows_x, rows_y], 1)  # (B, 8, 8)
    solution = np.linalg.solve(system, np.concatenate([x, y], 1)[..., None])[..., 0]
    homography = np.concatenate([solution, np.ones((b, 1))], 1).reshape(b, 3, 3)
    norm = _normalisation(height, width)
    return norm @ homography @ np.linalg.inv(norm)


def perspective_frames(batch: Tensor, corners: Tensor, mode: str) -> Tensor:
    """:func:`perspective` on a (B, T, 2, H, W) batch with checked (B, 4, 2) float64 CPU corners.

    Args:
        batch: event counts ``(B, T, 2, H, W)`` (the dispatcher adds the batch dimension).
        corners: where the centres of the top-left, top-right, bottom-right and bottom-left
            pixels go, as ``(y, x)`` pixel positions: ``(4, 2)`` for every sample or
            ``(B, 4, 2)``; they must make a convex quadrilateral in that order.
        mode: ``"bilinear"`` or ``"nearest"``.

    Shape:
        - frames: ``(B, T, 2, H, W)``; per-sample arguments ``(B,)`` (or ``(B, 2)``).
        - output: as :func:`perspective` gives for a batch.
    """
    b, _, _, height, width = batch.shape
    out_dtype = _output_dtype(batch.dtype, mode)
    if batch.numel() == 0:
        return batch.to(out_dtype, copy=True)
    work = _work_dtype(batch.dtype, mode)
    matrix = torch.from_numpy(_perspective_matrices(corners, height, width)).to(batch.device, work, non_blocking=True)
    base = _base_grid(height, width, batch.device, work)
    points = torch.cat([base, torch.ones_like(base[..., :1])], -1).view(1, height * width, 3)
    mapped = points @ matrix.transpose(1, 2)  # (B, H·W, 3), homogeneous
    grid = (mapped[..., :2] / mapped[..., 2:]).view(b, height, width, 2)
    return _sample(batch, grid, mode, work, out_dtype)


def perspective(
    frames: Tensor | EventBatch, corners: Sequence[Sequence[float]] | Tensor, *, mode: str = "bilinear"
) -> Tensor | EventBatch:
    """Warp every frame of each sequence by the homography that moves the frame's corners to ``corners``.

    One homography per sequence, solved on the host; all T·2 frames are folded into
    channels and sampled at one grid (kornia's ``warp_perspective`` and torchvision's
    ``perspective`` give the same result, frame by frame), as a camera tilted against the
    sensor plane would see the same contact. Pixels that come from outside the frame are
    zero. On a singleton axis the corners span [0, 1].

    On an EventBatch (:func:`perspective_events`) each event moves by the homography itself
    (the inverse of the frames' sampling map) to the nearest pixel, so counts are kept
    (frames sampled by ``nearest`` repeat or skip pixels where the warp stretches or
    squeezes; ``mode`` does not apply); events warped off the sensor are dropped, with the
    :class:`~event_transforms.events.EventsOutsideSensorWarning` binning gives.

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``, or an EventBatch.
        corners: where the centres of the top-left, top-right, bottom-right and bottom-left
            pixels go, as ``(y, x)`` pixel positions: ``(4, 2)`` for every sample or
            ``(B, 4, 2)``; they must make a convex quadrilateral in that order.
        mode: ``"bilinear"`` or ``"nearest"``.

    Returns:
        The warped frames, same shape and device; dtype as in :func:`rotate`.

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: same shape and device; float input keeps its dtype, integer input gives float32
          (``mode="nearest"`` keeps it).
        - corners: ``(4, 2)`` or ``(B, 4, 2)``.

    Example:
        >>> frames = torch.zeros(1, 2, 5, 5, dtype=torch.int16)
        >>> frames[0, 1, 0, 0] = 3  # the top-left corner
        >>> corners = [[1, 1], [0, 4], [4, 4], [4, 0]]  # the top-left corner moves to (1, 1)
        >>> out = perspective(frames, corners, mode="nearest")
        >>> out.dtype, out[0, 1].nonzero().tolist()
        (torch.int16, [[1, 1]])
    """
    kernel = kernel_for(perspective, frames)
    check_choice(mode, "mode", INTERPOLATIONS)
    batch, b, unbatch = batch_of(frames)
    return unbatch(kernel(batch, check_args("perspective", PERSPECTIVE_SPEC, b, corners=corners)["corners"].contiguous(), mode))


@register_kernel(perspective, EventBatch)
def perspective_events(batch: EventBatch, corners: Tensor, mode: str = "bilinear") -> EventBatch:
    """Kernel of :func:`perspective` for an EventBatch: each event moves by sample b's
    homography (the frame's corners to ``corners[b]``, in pixels; the inverse of the frame
    kernel's sampling map), to the nearest pixel; events off the sensor, or behind the
    homography's horizon, are dropped with a warning. Float64 arithmetic, one gather of
    the nine coefficients per event whatever B; host reads: the dropped and kept counts.

    Args:
        batch: the event streams.
        corners: ``(B, 4, 2)`` float64 ``(y, x)`` targets of the frame's corners, checked
            convex (as :func:`perspective` checks them).
        mode: not used (each event lands in one pixel).

    Shape:
        - batch: B streams, N events.
        - corners: ``(B, 4, 2)``.
        - output: B streams, at most N events (those on the sensor, in their order).

    Example:
        >>> from event_transforms import EventBatch
        >>> batch = EventBatch.from_streams([torch.tensor([[0, 0, 0, 1], [4, 4, 0, 1]])], sensor_size=(5, 5))
        >>> corners = torch.tensor([[[1.0, 1.0], [0.0, 4.0], [4.0, 4.0], [4.0, 0.0]]])
        >>> out = perspective_events(batch, corners)  # the top-left corner moves to (1, 1)
        >>> out.x.tolist(), out.y.tolist()
        ([1, 4], [1, 4])
    """
    if batch.num_events == 0 or len(batch) == 0:
        return batch
    height, width = batch.sensor_size
    norm = _normalisation(height, width)
    sampling = np.linalg.inv(norm) @ _perspective_matrices(corners, height, width) @ norm  # output pixel -> input pixel
    forward = torch.from_numpy(np.linalg.inv(sampling).reshape(-1, 9).T.copy()).to(batch.device, non_blocking=True)
    h = forward.index_select(1, batch.sample_index())  # (9, N)
    x, y = batch.x.to(torch.float64), batch.y.to(torch.float64)
    w = h[6] * x + h[7] * y + h[8]
    valid = w > 0
    w = torch.where(valid, w, torch.ones_like(w))
    return _keep_on_sensor(batch, (h[0] * x + h[1] * y + h[2]) / w, (h[3] * x + h[4] * y + h[5]) / w, valid)


register_kernel(perspective, Tensor)(perspective_frames)
