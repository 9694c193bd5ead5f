"""Warp kernels: the one affine warp behind rotation, resize and ``affine``, and the
perspective and elastic warps.

:func:`rotate`, :func:`resize` and :func:`affine` (rotation, scale, translation and shear
in one 2×3 matrix) are special cases of one private warp, ``_affine``
(``affine(angle=a)`` equals ``rotate(a)``, ``affine(scale=s)`` equals ``resize(s)``), about
the event centroid (:func:`center_of_mass`) by default. It folds the T·2 frames of a
sequence into channels and calls ``affine_grid`` and ``grid_sample`` once with a (B, 2, 3)
matrix built on the host (the same sampling as kornia's ``warp_affine``, without its
float64 matrix helpers and at a quarter of its dispatched ops; see
``benchmarks/kornia_warp.py``), so one sampling grid serves every frame of a sequence (the
grasp keeps its orientation), no (B·T) grids are built, and the device is never asked for
a number.

:func:`perspective` and :func:`elastic` are warps the affine matrix cannot express; they
fold the frames the same way and sample them at one grid per sequence built from a host
homography or a smoothed displacement field (what kornia's ``warp_perspective`` and
``elastic_transform2d`` compute, with a fraction of their dispatched ops).
"""

from __future__ import annotations

import functools
import math
import warnings
from collections.abc import Sequence

import numpy as np
import torch
from torch import Tensor

from .._params import Param, check_args
from .._validation import INTERPOLATIONS, as_batch, as_number, check_choice, check_frames, describe, on_host
from ..events.batch import EventBatch
from ._dispatch import batch_of, call_kernel, kernel_for, register_kernel
from ._event_ops import _compact, _round_to, warn_dropped

__all__ = [
    "center_of_mass",
    "event_centroid",
    "rotate", "rotate_frames", "rotate_events",
    "resize", "resize_frames", "resize_events",
    "affine", "affine_frames", "affine_events",
    "perspective", "perspective_frames", "perspective_events",
    "elastic", "elastic_frames", "elastic_events",
]

Center = str | Sequence[float] | Tensor
Scalars = float | Sequence[float] | Tensor
Pairs = Sequence[float] | Tensor


# --------------------------------------------------------------------------- declarations
# Each operation's per-sample arguments, declared once: the dispatcher checks its arguments
# against it (check_args), the module's params_spec returns it (check_tree).


def _convex(corners: Tensor) -> str | None:
    """Whether (B, 4, 2) (y, x) corners make convex quadrilaterals in the frame's corner order."""
    edges = corners.roll(-1, dims=1) - corners  # (B, 4, 2) as (dy, dx)
    after = edges.roll(-1, dims=1)
    turns = edges[..., 1] * after[..., 0] - edges[..., 0] * after[..., 1]
    if bool((turns > 0).all()):
        return None
    return ("make a convex quadrilateral in the order top-left, top-right, bottom-right, bottom-left "
            "(as the frame's corners do)")


#: :func:`rotate`: degrees, counter-clockwise.
ROTATE_SPEC = {"angle": Param("float")}
#: :func:`resize`: a zoom factor > 0.
RESIZE_SPEC = {"scale": Param("float", low=0.0, low_open=True)}
#: :func:`affine`: rotation, zoom, translation (dy, dx) and shear (x, y) in (-90, 90) degrees.
AFFINE_SPEC = {
    **ROTATE_SPEC, **RESIZE_SPEC, "translate": Param("float", shape=(2,)),
    "shear": Param("float", shape=(2,), low=-90.0, high=90.0, low_open=True, high_open=True),
}
#: :func:`perspective`: where the frame's four corners go, (y, x), a convex quadrilateral.
PERSPECTIVE_SPEC = {"corners": Param("float", shape=(4, 2), rule=_convex)}


def elastic_spec(shape: Sequence[int]) -> dict[str, Param]:
    """:func:`elastic`'s per-sample arguments for a batch ``shape`` (B, T, 2, H, W): the
    strength ``alpha`` >= 0 and the displacement noise in [-1, 1]."""
    return {"alpha": Param("float", low=0.0), "noise": Param("float", shape=(2, *shape[-2:]), low=-1.0, high=1.0)}


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


def _check_center(center: object, batch: int | None = None) -> Center:
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


def _work_dtype(dtype: torch.dtype, mode: str) -> torch.dtype:
    if dtype == torch.float64 or (mode == "nearest" and dtype in (torch.int32, torch.int64)):
        return torch.float64  # exact for large counts
    return torch.float32


def _output_dtype(dtype: torch.dtype, mode: str) -> torch.dtype:
    if mode == "nearest" or dtype.is_floating_point:
        return dtype
    return torch.float32


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


def _warp(batch: Tensor, theta: Tensor, mode: str) -> Tensor:
    """Sample every frame of sequence b through its (2, 3) matrix ``theta[b]`` (normalised
    coordinates of ``grid_sample`` with ``align_corners=True``, zero padding): one
    ``affine_grid`` and one ``grid_sample`` for all T·2 frames, folded into channels. The
    one warp of rotate, resize, affine and stretch."""
    b, t, p, height, width = batch.shape
    work, out_dtype = _work_dtype(batch.dtype, mode), _output_dtype(batch.dtype, mode)
    theta = theta.to(batch.device, work)
    if height == 1 or width == 1:
        with warnings.catch_warnings():  # unit-size axes map to pixel 0, as intended here
            warnings.filterwarnings("ignore", message="Since version 1.3.0, affine_grid")
            grid = torch.nn.functional.affine_grid(theta, [b, t * p, height, width], align_corners=True)
    else:
        grid = torch.nn.functional.affine_grid(theta, [b, t * p, height, width], align_corners=True)
    folded = batch.reshape(b, t * p, height, width).to(work)
    warped = torch.nn.functional.grid_sample(folded, grid, mode=mode, padding_mode="zeros", align_corners=True)
    return warped.view(b, t, p, height, width).to(out_dtype)


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
    center = _check_center(center, b)
    angle_t = check_args("rotate", ROTATE_SPEC, b, angle=angle)["angle"]
    return restore(call_kernel(rotate, batch, angle_t, center=center, mode=check_choice(mode, "mode", INTERPOLATIONS)))


def resize(
    inputs: Tensor | EventBatch, scale: Scalars, *, center: Center = "mass", mode: str = "bilinear"
) -> Tensor | EventBatch:
    """Zoom each sequence by ``scale`` about its centre, keeping H×W (zero margin).

    ``scale`` is the paper's β = target object size / source object size: 1.25 makes a
    12 mm bolt's contact look like a 15 mm bolt's, 0.83 shrinks an 18 mm one. With
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
    center = _check_center(center, b)
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
    center = _check_center(center, b)
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


# --------------------------------------------------------------------------- perspective and elastic


def _image_corners(height: int, width: int) -> Tensor:
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


def _perspective_matrices(corners: Tensor, height: int, width: int) -> np.ndarray:
    """(B, 3, 3) float64 host matrices taking an output grid point (u, v, 1) to its source
    point in homogeneous normalised coordinates: the homography from ``corners`` back to the
    frame's corners (four point pairs, eight unknowns, one solve per sample), conjugated by
    the normalisation. NumPy, not torch: host numbers, no dispatch."""
    target = np.asarray(corners.tolist(), dtype=np.float64)[..., ::-1]  # (B, 4, 2) as (x, y): output
    source = _image_corners(height, width).numpy()[:, ::-1]  # (4, 2) as (x, y): input
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
    T·2 frames of a sequence share the field (the membrane deforms, the contact keeps its
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


register_kernel(perspective, Tensor)(perspective_frames)
register_kernel(elastic, Tensor)(elastic_frames)


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
    warn_dropped(moved, outside_sensor=outside, stacklevel=5)
    return _compact(moved, ~outside)


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
