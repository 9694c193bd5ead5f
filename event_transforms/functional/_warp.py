"""The warp core (private), shared by rotate/resize/affine, stretch, perspective and elastic.

The event centroid of a sequence (:func:`center_of_mass`, float64 moments, the image centre
for an empty sequence), the host-built sampling matrices, and ``_warp``: one ``affine_grid``
and one ``grid_sample`` for all T·2 frames of a sequence folded into channels. Shared
helpers of the non-affine warps (normalisation, base grid, bilinear reads of a field, the
events kept on the sensor) live here too, so no topic file imports another's private names.
"""

from __future__ import annotations

import functools
import math
import warnings
from collections.abc import Sequence

import numpy as np
import torch
from torch import Tensor

from .._compile import compilable
from .._validation import as_batch, check_choice, check_frames, describe
from ..events.batch import EventBatch
from ..events.dropped import counting, record_dropped
from ._event_ops import _compact, _round_to
from ._frame_ops import _output_dtype, _work_dtype


Center = str | Sequence[float] | Tensor


def center_of_mass(frames: Tensor) -> Tensor:
    """Event centroid of each sequence, both polarities and all frames, as (y, x).

    Computed in float64 whatever the input dtype; an empty sequence falls back to the
    image centre ((H - 1) / 2, (W - 1) / 2). NaN and ±Inf pixels carry no mass (the NaN
    policy of the warps: a non-finite pixel stays local, it reaches only the output pixels
    whose interpolation reads it, and never moves the centre of a whole sample).

    Args:
        frames: event counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.

    Returns:
        float64 tensor ``(2,)`` for one sequence or ``(B, 2)`` for a batch, on the
        frames' device, in pixel coordinates (row, column).

    Shape:
        - frames: ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        - output: ``(2,)`` or ``(B, 2)`` float ``(y, x)`` on the frames' device.

    Example:
        >>> frames = torch.zeros(3, 2, 5, 7)
        >>> frames[0, 1, 1, 2] = 1.0
        >>> frames[2, 0, 3, 4] = 3.0
        >>> center_of_mass(frames)
        tensor([2.5000, 3.5000], dtype=torch.float64)
    """
    batch, unbatch = as_batch(check_frames(frames))
    return unbatch(_center_of_mass(batch))


def _center_of_mass(batch: Tensor) -> Tensor:
    moments = _mass_moments(batch)
    return moments[:, 1:] / moments[:, :1]


#: Mass of the prior at the image centre (a power of two, so scaling by it is exact).
_PRIOR = 2.0**-900


@functools.lru_cache(maxsize=32)
def _moment_weights(height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Host constants of :func:`_mass_moments`: the prior ``(3,)`` and the ``(H + W, 3)``
    matrix taking row sums to ``[mass, y moment, 0]`` and column sums to ``[0, 0, x moment]``."""
    weights = np.zeros((height + width, 3))
    weights[:height, 0] = 1.0
    weights[:height, 1] = np.arange(height)
    weights[height:, 2] = np.arange(width)
    prior = np.array([_PRIOR, _PRIOR * (height - 1) / 2, _PRIOR * (width - 1) / 2])
    return prior, weights


def _mass_moments(batch: Tensor, *, host: bool = True) -> Tensor:
    """(B, 3) float64 ``[M, M·y, M·x]`` of each sequence: its event mass M and first
    moments, plus a prior of mass 2**-900 at the image centre.

    The prior is far below float64 resolution beside any real mass, so
    ``moments[:, 1:] / moments[:, :1]`` is the centroid (to ~1e-250), and exactly the
    image centre for an empty sequence: no ``where``, no branch on the data.
    About ten device ops and no host synchronisation; with ``host=False`` the constants are
    made on the device (no host-to-device copy, as CUDA-graph capture requires).
    """
    height, width = batch.shape[-2:]
    weight = _mass_weight(batch)
    margins = torch.cat([weight.sum(dim=2, dtype=torch.float64), weight.sum(dim=1, dtype=torch.float64)], dim=1)
    if not host or torch.compiler.is_compiling():
        prior, weights = _moment_weights_tensors(height, width, batch.device)
    else:
        prior, weights = (torch.from_numpy(a).to(batch.device) for a in _moment_weights(height, width))
    return torch.addmm(prior, margins, weights)


def _mass_weight(batch: Tensor) -> Tensor:
    """(B, H, W) event mass per pixel: the T·2 frames of each sequence summed (float32, or
    float64 for float64 and 32/64-bit integer input). NaN and ±Inf pixels carry no mass."""
    b, t, p, height, width = batch.shape
    # One batched matrix product (much faster than a strided reduction); float32 is exact
    # for whole counts below 2**24 per pixel.
    exact = batch.dtype in (torch.float64, torch.int32, torch.int64)
    acc = torch.float64 if exact else torch.float32
    ones = torch.ones(1, t * p, dtype=acc, device=batch.device)
    flat = batch.reshape(b, t * p, height * width).to(acc)
    if batch.is_floating_point():  # one NaN pixel must not move the centre of a whole sample
        if flat.device.type == "cpu" and not torch.compiler.is_compiling():
            # a finite sum of ones times a column means every entry of it is finite, where
            # nan_to_num changes nothing: the same product, without a copy of the batch.
            # A CPU value read with tolist, as CPU parameters are: nothing waits (other
            # devices keep the one fused nan_to_num pass and read nothing)
            weight = torch.matmul(ones, flat)
            if weight.isfinite().all().tolist():
                return weight.view(b, height, width)
        flat = torch.nan_to_num(flat, nan=0.0, posinf=0.0, neginf=0.0)
    return torch.matmul(ones, flat).view(b, height, width)


def _moment_weights_tensors(height: int, width: int, device: torch.device) -> tuple[Tensor, Tensor]:
    """:func:`_moment_weights` built with tensor ops on ``device`` (for ``torch.compile`` and
    CUDA-graph capture: fills and ``arange``, no host-to-device copy)."""
    f64 = torch.float64
    rows, cols = torch.zeros(width, dtype=f64, device=device), torch.zeros(height, dtype=f64, device=device)
    weights = torch.stack(
        [
            torch.cat([torch.ones(height, dtype=f64, device=device), rows]),
            torch.cat([torch.arange(height, dtype=f64, device=device), rows]),
            torch.cat([cols, torch.arange(width, dtype=f64, device=device)]),
        ],
        dim=1,
    )
    prior = _constants([_PRIOR, _PRIOR * (height - 1) / 2, _PRIOR * (width - 1) / 2], device)
    return prior, weights


def _constants(values: Sequence[float], device: torch.device) -> Tensor:
    """A float64 vector of host numbers made on ``device`` by fills (no host-to-device copy)."""
    return torch.stack([torch.full((), v, dtype=torch.float64, device=device) for v in values])


def check_center(center: object, batch: int | None = None) -> Center:
    """``"mass"``, ``"image"``, a ``(y, x)`` pair, or (with ``batch``) a ``(B, 2)`` tensor."""
    if isinstance(center, str):
        return check_choice(center, "center", ("mass", "image"))
    try:
        value = torch.as_tensor(center, dtype=torch.float64)
    except (TypeError, ValueError, RuntimeError):
        raise TypeError(f"center must be 'mass', 'image' or (y, x), got {center!r}") from None
    shapes = [(2,)] if batch is None else [(2,), (batch, 2)]
    if tuple(value.shape) not in shapes:
        expected = "'mass', 'image' or (y, x)" + ("" if batch is None else f" or a ({batch}, 2) tensor")
        raise ValueError(f"center must be {expected}, got {describe(center)}")
    if not bool(value.isfinite().all()):
        raise ValueError(f"center must be finite, got {describe(center)}")
    return center  # type: ignore[return-value]  # a checked (y, x) sequence or tensor


def _warp(batch: Tensor, theta: Tensor, mode: str) -> Tensor:
    """Sample every frame of sequence b through its (2, 3) matrix ``theta[b]`` (normalised
    coordinates of ``grid_sample`` with ``align_corners=True``, zero padding): one
    ``affine_grid`` and one ``grid_sample`` for all T·2 frames, folded into channels. The
    one warp of rotate, resize, affine and stretch."""
    b, t, p, height, width = batch.shape
    work, out_dtype = _work_dtype(batch.dtype, mode), _output_dtype(batch.dtype, mode)
    theta = theta.to(batch.device, work)
    folded = batch.reshape(b, t * p, height, width).to(work)
    if height == 1 or width == 1:
        with warnings.catch_warnings():  # unit-size axes map to pixel 0, as intended here
            warnings.filterwarnings("ignore", message="Since version 1.3.0, affine_grid")
            warped = _affine_sample.eager(folded, theta, mode)  # type: ignore[attr-defined]
    else:
        warped = _affine_sample(folded, theta, mode)
    return warped.view(b, t, p, height, width).to(out_dtype)


@compilable
def _affine_sample(folded: Tensor, theta: Tensor, mode: str) -> Tensor:
    """``grid_sample`` of (B, C, H, W) ``folded`` at the ``affine_grid`` of (B, 2, 3) ``theta``
    (``align_corners=True``, zero padding): the compiled path's unit of the warp."""
    grid = torch.nn.functional.affine_grid(theta, list(folded.shape), align_corners=True)
    return torch.nn.functional.grid_sample(folded, grid, mode=mode, padding_mode="zeros", align_corners=True)


def _theta_on_device(batch: Tensor, angle: Tensor | None, scale: Tensor | None, center: Center) -> Tensor:
    """(B, 2, 3) float64 sampling matrices built with tensor ops only, on the frames'
    device (the path for ``torch.compile`` and for parameters already on an accelerator):
    the same numbers as :func:`_sampling_matrices`, up to float64 rounding."""
    b, _, _, height, width = batch.shape
    f64, device = torch.float64, batch.device
    angle = torch.zeros(b, dtype=f64, device=device) if angle is None else angle.to(device, f64)
    scale = torch.ones(b, dtype=f64, device=device) if scale is None else scale.to(device, f64)
    radians = torch.deg2rad(angle)
    cos, sin = torch.cos(radians) / scale, torch.sin(radians) / scale
    a = torch.stack([torch.stack([cos, -sin], 1), torch.stack([sin, cos], 1)], 1)  # (B, 2, 2), (x, y)
    d = _constants([2.0 / (width - 1) if width > 1 else 1.0, 2.0 / (height - 1) if height > 1 else 1.0], device)
    e = _constants([-1.0 if width > 1 else 0.0, -1.0 if height > 1 else 0.0], device)
    linear = d.view(1, 2, 1) * a / d.view(1, 1, 2)
    per_centre = d.view(1, 2, 1) * (torch.eye(2, dtype=f64, device=device) - a)  # on (c_x, c_y)
    constant = e - linear @ e
    if isinstance(center, str) and center == "mass":
        moments = _mass_moments(batch, host=False)
        yx = moments[:, 1:] / moments[:, :1]
    elif isinstance(center, str):
        yx = _constants([(height - 1) / 2, (width - 1) / 2], device).expand(b, 2)
    else:
        yx = torch.as_tensor(center, dtype=f64).to(device).expand(b, 2)
    shift = constant + per_centre[:, :, 1] * yx[:, :1] + per_centre[:, :, 0] * yx[:, 1:]  # (B, 2)
    return torch.cat([linear, shift.unsqueeze(2)], dim=2)


def _sampling_matrices(
    angle: np.ndarray,
    scale: np.ndarray,
    height: int,
    width: int,
    *,
    shear: Tensor | None = None,
    translate: Tensor | None = None,
) -> np.ndarray:
    """(B, 6, 3) float64 host matrices: ``theta = (matrix @ [1, c_y, c_x]).reshape(2, 3)``.

    In pixels, output pixel d samples ``c + A (d - c - t)`` with ``A = L^-1`` in (x, y)
    order, the inverse of the forward linear part ``L = s R(θ) Sh`` (for a pure rotation
    and zoom ``A = R(θ)^T / s``, written out). ``grid_sample`` with ``align_corners=True``
    sees ``u = D x + e`` (D = 2 / (n - 1), e = -1; D = 1, e = 0 on a singleton axis, as
    kornia does), so ``theta = [D A D^-1 | D (I - A) c + e - D A D^-1 e - D A t]``, which is
    linear in ``[1, c_y, c_x]``. Each row of ``matrix`` holds one entry of theta as
    coefficients of ``[1, c_y, c_x]``, so a device centroid enters through one ``bmm`` with
    the moments ``[M, M c_y, M c_x]`` divided by M. NumPy, not torch: host numbers, no dispatch.
    """
    radians = np.deg2rad(angle.astype(np.float64))
    if shear is None:
        cos, sin = np.cos(radians) / scale, np.sin(radians) / scale
        a = np.stack([np.stack([cos, -sin], 1), np.stack([sin, cos], 1)], 1)  # (B, 2, 2), (x, y) order
    else:
        cos, sin = np.cos(radians), np.sin(radians)
        shear_np = np.tan(np.deg2rad(np.asarray(shear.tolist(), dtype=np.float64)))  # (B, 2): x, y
        sx, sy = shear_np[:, 0], shear_np[:, 1]
        rotation = np.stack([np.stack([cos, sin], 1), np.stack([-sin, cos], 1)], 1)
        shears = np.stack([np.stack([1 + sx * sy, sx], 1), np.stack([sy, np.ones_like(sy)], 1)], 1)
        a = np.linalg.inv(scale[:, None, None] * rotation @ shears)
    d = np.array([2.0 / (width - 1) if width > 1 else 1.0, 2.0 / (height - 1) if height > 1 else 1.0])
    e = np.array([-1.0 if width > 1 else 0.0, -1.0 if height > 1 else 0.0])
    linear = d[None, :, None] * a / d[None, None, :]  # D A D^-1
    per_centre = d[None, :, None] * (np.eye(2) - a)  # D (I - A), columns on (c_x, c_y)
    matrix = np.zeros((angle.shape[0], 2, 3, 3))
    matrix[:, :, :2, 0] = linear
    matrix[:, :, 2, 0] = e - linear @ e
    if translate is not None:
        shift_xy = np.asarray(translate.tolist(), dtype=np.float64)[:, ::-1]  # (B, 2) as (x, y)
        matrix[:, :, 2, 0] -= d[None, :] * (a @ shift_xy[:, :, None])[:, :, 0]
    matrix[:, :, 2, 1] = per_centre[:, :, 1]
    matrix[:, :, 2, 2] = per_centre[:, :, 0]
    return matrix.reshape(-1, 6, 3)


def image_corners(height: int, width: int) -> Tensor:
    """(4, 2) float64 (y, x) corners of the frame: top-left, top-right, bottom-right, bottom-left
    pixel centres (a singleton axis spans [0, 1], so the quadrilateral never degenerates)."""
    bottom, right = max(height - 1, 1), max(width - 1, 1)
    return torch.tensor([[0.0, 0.0], [0.0, right], [bottom, right], [bottom, 0.0]], dtype=torch.float64)


def _normalisation(height: int, width: int) -> np.ndarray:
    """3×3 map from pixel (x, y, 1) to ``grid_sample``'s ``align_corners=True`` coordinates
    (D = 2 / (n - 1), e = -1; D = 1, e = 0 on a singleton axis, as in :func:`_sampling_matrices`)."""
    d = [2.0 / (width - 1) if width > 1 else 1.0, 2.0 / (height - 1) if height > 1 else 1.0]
    e = [-1.0 if width > 1 else 0.0, -1.0 if height > 1 else 0.0]
    return np.array([[d[0], 0.0, e[0]], [0.0, d[1], e[1]], [0.0, 0.0, 1.0]])


def _sample(batch: Tensor, grid: Tensor, mode: str, work: torch.dtype, out_dtype: torch.dtype) -> Tensor:
    """All T·2 frames of each sequence folded into channels and sampled at one (B, H, W, 2) grid."""
    b, t, p, height, width = batch.shape
    folded = batch.reshape(b, t * p, height, width).to(work)
    warped = torch.nn.functional.grid_sample(folded, grid.to(work), mode=mode, padding_mode="zeros", align_corners=True)
    return warped.view(b, t, p, height, width).to(out_dtype)


def _base_grid(height: int, width: int, device: torch.device, dtype: torch.dtype) -> Tensor:
    """(H, W, 2) identity grid in ``align_corners=True`` normalised (x, y) coordinates."""
    norm = _normalisation(height, width)
    xs = torch.arange(width, device=device, dtype=dtype).mul_(norm[0, 0]).add_(norm[0, 2])
    ys = torch.arange(height, device=device, dtype=dtype).mul_(norm[1, 1]).add_(norm[1, 2])
    return torch.stack(torch.meshgrid(xs, ys, indexing="xy"), -1)


def _keep_on_sensor(batch: EventBatch, x: Tensor, y: Tensor, valid: Tensor | None = None) -> EventBatch:
    """``batch`` with float coordinates ``x, y`` rounded to the nearest pixel; the events that
    land off the sensor (or are not ``valid``) dropped with the binning's
    :class:`~event_transforms.events.EventsOutsideSensorWarning`. Host reads: the warning's counts
    and the kept counts."""
    height, width = batch.sensor_size
    moved = batch._replace(x=_round_to(x, torch.int16), y=_round_to(y, torch.int16))
    outside = (moved.x < 0) | (moved.x >= width) | (moved.y < 0) | (moved.y >= height)
    if valid is not None:
        outside |= ~valid
    if counting():  # dropped by design: counted in a count_dropped block, never warned
        record_dropped("off_sensor", outside)
    return _compact(moved, ~outside)


def _bilinear(field: Tensor, bases: tuple[Tensor, ...], y: Tensor, x: Tensor, height: int, width: int) -> list[Tensor]:
    """The flat ``field`` planes starting at each of ``bases`` (per event) read bilinearly at
    ``(y, x)`` clamped to the frame."""
    y, x = y.clamp(0, height - 1), x.clamp(0, width - 1)
    y0, x0 = y.floor(), x.floor()
    wy, wx = y - y0, x - x0
    y0, x0 = y0.to(torch.int64), x0.to(torch.int64)
    y1, x1 = (y0 + 1).clamp_max(height - 1), (x0 + 1).clamp_max(width - 1)
    out = []
    for base in bases:
        top = torch.lerp(_at(field, base, y0, x0, width), _at(field, base, y0, x1, width), wx)
        bottom = torch.lerp(_at(field, base, y1, x0, width), _at(field, base, y1, x1, width), wx)
        out.append(torch.lerp(top, bottom, wy))
    return out


def _at(field: Tensor, base: Tensor, y: Tensor, x: Tensor, width: int) -> Tensor:
    return field.index_select(0, base + y * width + x)


def axis_radians(covariance: Tensor) -> Tensor:
    """Angle of the major axis of each (B, 3) ``[c_yy, c_xx, c_xy]``, counter-clockwise on the
    displayed image (row 0 at the top), in (-π/2, π/2]; 0 for an isotropic or empty sequence."""
    c_yy, c_xx, c_xy = covariance.unbind(1)
    # in pixel coordinates (y down) the major axis is at 0.5·atan2(2 c_xy, c_xx - c_yy);
    # on the displayed image (y up) the angle changes sign
    angle = -0.5 * torch.atan2(2 * c_xy, c_xx - c_yy)
    return torch.where(angle <= -math.pi / 2, angle + math.pi, angle)
