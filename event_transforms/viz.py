"""Pictures of event frames: ON and OFF counts in two colours, as the paper's Fig. 1.

Built on torchvision's ``make_grid`` and ``save_image`` (Pillow, which torchvision already
needs, writes the PNG); no plotting library is needed.
"""

from __future__ import annotations

__all__ = ["frames_to_rgb", "make_event_grid", "save_event_grid", "compare_transform"]

import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import torch
from torch import Tensor
from ._validation import check_frames

Color = Sequence[int]

ON_COLOR = (20, 90, 255)
OFF_COLOR = (230, 40, 30)
BACKGROUND = (255, 255, 255)


def _color(value: Color, name: str) -> Tensor:
    color = torch.as_tensor(value, dtype=torch.float64)
    if color.shape != (3,) or bool(((color < 0) | (color > 255)).any()):
        raise ValueError(f"{name} must be three integers in [0, 255], got {value!r}")
    return color


def frames_to_rgb(
    frames: Tensor,
    *,
    vmax: float | Tensor | None = None,
    gamma: float = 0.5,
    on_color: Color = ON_COLOR,
    off_color: Color = OFF_COLOR,
    background: Color = BACKGROUND,
) -> Tensor:
    """Colour event frames: ON counts in ``on_color``, OFF counts in ``off_color``.

    Each polarity's count is scaled to ``(count / vmax) ** gamma`` (clipped at 1) and
    pulls the pixel from ``background`` towards its colour; a pixel with both polarities
    mixes them.

    Args:
        frames: counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)`` (any real dtype).
        vmax: count shown at full colour: a number, a (B,) tensor (one per sequence), or
            ``None`` for each sequence's largest count.
        gamma: exponent applied to the scaled counts (< 1 brightens sparse events).
        on_color, off_color, background: RGB triples in [0, 255].

    Returns:
        uint8 tensor ``(T, 3, H, W)`` or ``(B, T, 3, H, W)`` on the CPU.

    Example:
        >>> frames = torch.zeros(1, 2, 1, 3)
        >>> frames[0, 1, 0, 0] = 4.0  # ON
        >>> frames[0, 0, 0, 1] = 2.0  # OFF
        >>> frames_to_rgb(frames, gamma=1.0)[0, :, 0].T.tolist()
        [[20, 90, 255], [242, 148, 142], [255, 255, 255]]
    """
    check_frames(frames)
    if not (isinstance(gamma, (int, float)) and gamma > 0):
        raise ValueError(f"gamma must be a positive number, got {gamma!r}")
    on, off, back = (
        _color(on_color, "on_color"),
        _color(off_color, "off_color"),
        _color(background, "background"),
    )
    batch = frames.detach().to("cpu", torch.float64)
    single = batch.dim() == 4
    if single:
        batch = batch.unsqueeze(0)
    if vmax is None:
        scale = batch.flatten(1).amax(dim=1) if batch.numel() else torch.ones(batch.shape[0])
    else:
        scale = torch.as_tensor(vmax, dtype=torch.float64).expand(batch.shape[0])
    scale = torch.where(scale > 0, scale, torch.ones_like(scale)).view(-1, 1, 1, 1, 1)
    level = (batch.clamp(min=0) / scale).clamp(max=1) ** gamma  # (B, T, 2, H, W)
    off_level, on_level = level[:, :, 0:1], level[:, :, 1:2]
    rgb = (
        back.view(1, 1, 3, 1, 1)
        - on_level * (back - on).view(1, 1, 3, 1, 1)
        - off_level * (back - off).view(1, 1, 3, 1, 1)
    )
    rgb = rgb.round().clamp(0, 255).to(torch.uint8)
    return rgb.squeeze(0) if single else rgb


def make_event_grid(
    frames: Tensor,
    *,
    nrow: int | None = None,
    padding: int = 2,
    pad_value: int = 128,
    upscale: int = 1,
    **color: Any,
) -> Tensor:
    """One image of a sequence (frames left to right) or a batch (one row per sequence).

    Args:
        frames: counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        nrow: images per row (default: 12 for one sequence, T for a batch).
        padding, pad_value: gap between images and its grey level.
        upscale: integer magnification (nearest neighbour) of every frame.
        **color: passed to :func:`frames_to_rgb` (``vmax``, ``gamma``, colours).

    Returns:
        uint8 image ``(3, H', W')``.

    Example:
        >>> make_event_grid(torch.zeros(2, 5, 2, 7, 11), padding=1).shape
        torch.Size([3, 17, 61])
    """
    rgb = frames_to_rgb(frames, **color)
    if isinstance(upscale, bool) or not isinstance(upscale, int) or upscale < 1:
        raise ValueError(f"upscale must be a positive integer, got {upscale!r}")
    if upscale > 1:
        rgb = rgb.repeat_interleave(upscale, dim=-2).repeat_interleave(upscale, dim=-1)
    if nrow is None:
        nrow = rgb.shape[1] if rgb.dim() == 5 else min(12, rgb.shape[0])
    images = rgb.flatten(0, -4)
    if images.shape[0] == 0:
        raise ValueError(f"frames must hold at least one frame, got shape {tuple(frames.shape)}")
    from torchvision.utils import make_grid  # imported on first use: torchvision is slow to import

    return make_grid(images, nrow=max(1, int(nrow)), padding=padding, pad_value=pad_value)


def save_event_grid(frames: Tensor, path: str | os.PathLike[str], **kwargs: Any) -> Path:
    """Write :func:`make_event_grid` of ``frames`` to a PNG file and return its path.

    Example:
        >>> import tempfile, pathlib
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "grasp.png"
        >>> save_event_grid(torch.zeros(3, 2, 4, 4), path).exists()
        True
    """
    return _write(make_event_grid(frames, **kwargs), path)


def _write(image: Tensor, path: str | os.PathLike[str]) -> Path:
    """Save a uint8 (3, H, W) image losslessly (PNG by the file's suffix)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    from torchvision.utils import save_image

    save_image(image.to(torch.float32) / 255, path)  # save_image rounds back to the same bytes
    return path


def compare_transform(
    frames: Tensor,
    transform: Callable[..., Tensor],
    path: str | os.PathLike[str] | None = None,
    *,
    generator: torch.Generator | None = None,
    metadata: Any = None,
    **kwargs: Any,
) -> Tensor:
    """Before/after picture of a transform: for each sequence, its row and the result's.

    Both rows of a sequence share one colour scale (the larger of the two maxima), so
    added or removed events show as brighter or fainter colour.

    Args:
        frames: counts ``(T, 2, H, W)`` or ``(B, T, 2, H, W)``.
        transform: an event transform, called as
            ``transform(frames, generator=generator, metadata=metadata)``, or a callable
            ``frames -> frames``.
        path: where to write the PNG (optional).
        generator: passed to the transform.
        metadata: passed to the transform.
        **kwargs: passed to :func:`make_event_grid`.

    Returns:
        The uint8 image ``(3, H', W')``.

    Example:
        >>> from event_transforms import HorizontalFlip
        >>> compare_transform(torch.ones(4, 2, 5, 6), HorizontalFlip(), padding=0).shape
        torch.Size([3, 10, 24])
    """
    from .transforms.base import as_transform

    check_frames(frames)
    with torch.no_grad():
        after = as_transform(transform)(frames, generator=generator, metadata=metadata)
    before = frames.unsqueeze(0) if frames.dim() == 4 else frames
    after = after.unsqueeze(0) if after.dim() == 4 else after
    if after.shape != before.shape:
        raise ValueError(
            f"the transform changed the shape from {tuple(before.shape)} to {tuple(after.shape)}"
        )
    pairs = torch.stack([before.detach().cpu().double(), after.detach().cpu().double()], dim=1)
    if "vmax" not in kwargs:
        kwargs["vmax"] = pairs.flatten(1).amax(dim=1).repeat_interleave(2) if pairs.numel() else None
    grid = make_event_grid(pairs.flatten(0, 1), **kwargs)
    if path is not None:
        _write(grid, path)
    return grid
