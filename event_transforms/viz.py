"""Pictures of event frames: ON and OFF counts in two colours, as the paper's Fig. 1.

The grids (:func:`make_event_grid`, :func:`compare_transform`) are built on torchvision's
``make_grid`` and ``save_image`` (Pillow writes the PNG); no plotting library is needed.
torchvision is not a dependency of the base install: it comes with the ``viz`` extra
(``pip install 'event-transforms[viz]'``), and a grid without it raises an
:class:`ImportError` that says so.
The labelled figures (:func:`plot_transform`: rows named before/after, a polarity legend,
frame times, the frames where the transform acts; :func:`plot_scene`: training above
deployment, the scene's gaps in the title, event-rate curves and histograms of the
contact width, angle and onset beside the frames) need matplotlib, also in the ``viz`` extra (and in ``app``), imported on first use.
"""

from __future__ import annotations

__all__ = [
    "frames_to_rgb",
    "make_event_grid",
    "save_event_grid",
    "compare_transform",
    "acting_frames",
    "plot_transform",
    "plot_scene",
]

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
    return _torchvision_utils().make_grid(images, nrow=max(1, int(nrow)), padding=padding, pad_value=pad_value)


def save_event_grid(frames: Tensor, path: str | os.PathLike[str], **kwargs: Any) -> Path:
    """Write :func:`make_event_grid` of ``frames`` to a PNG file and return its path.

    Example:
        >>> import tempfile, pathlib
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "frames.png"
        >>> save_event_grid(torch.zeros(3, 2, 4, 4), path).exists()
        True
    """
    return _write(make_event_grid(frames, **kwargs), path)


def _write(image: Tensor, path: str | os.PathLike[str]) -> Path:
    """Save a uint8 (3, H, W) image losslessly (PNG by the file's suffix)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    _torchvision_utils().save_image(image.to(torch.float32) / 255, path)  # save_image rounds back to the same bytes
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


# --------------------------------------------------------------------------- labelled figures


def _torchvision_utils() -> Any:
    """``torchvision.utils``, imported on first use (it is slow to import, and an extra)."""
    try:
        import torchvision.utils  # type: ignore[import-untyped]
    except ImportError as error:
        raise ImportError(
            "event_transforms.viz draws its grids with torchvision, which is not installed: "
            "pip install 'event-transforms[viz]'",
            name="torchvision",
        ) from error
    return torchvision.utils


def _pyplot() -> Any:
    try:
        import matplotlib

        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt
    except ImportError:  # pragma: no cover - depends on the environment
        raise ImportError(
            "the labelled figures need matplotlib: pip install 'event-transforms[viz]' (or [app])",
            name="matplotlib",
        ) from None
    return plt


def acting_frames(before: Tensor, after: Tensor, count: int = 8) -> Tensor:
    """Indices (sorted) of the ``count`` frames that the transform changed most.

    The change of frame t is the sum of ``|after - before|`` over its pixels and
    polarities; frames it did not change at all are never picked ahead of changed ones, and
    an identity gives ``count`` evenly spaced frames.

    Example:
        >>> before = torch.zeros(6, 2, 3, 3)
        >>> after = before.clone()
        >>> after[4, 0, 1, 1] = 2.0
        >>> after[1, 1, 0, 0] = 1.0
        >>> acting_frames(before, after, 2).tolist()
        [1, 4]
    """
    check_frames(before)
    if before.shape != after.shape or before.dim() != 4:
        raise ValueError(
            f"before and after must be one sequence (T, 2, H, W) each, got {tuple(before.shape)} and "
            f"{tuple(after.shape)}"
        )
    t = before.shape[0]
    count = max(1, min(int(count), t))
    change = (after.detach().double().cpu() - before.detach().double().cpu()).abs().sum((1, 2, 3))
    if float(change.sum()) == 0:
        return torch.linspace(0, t - 1, count).round().long().unique()
    return change.argsort(descending=True, stable=True)[:count].sort().values


def _legend(ax: Any) -> None:
    from matplotlib.patches import Patch

    ax.legend(
        handles=[
            Patch(color=tuple(c / 255 for c in ON_COLOR), label="ON (channel 1)"),  # type: ignore[arg-type]
            Patch(color=tuple(c / 255 for c in OFF_COLOR), label="OFF (channel 0)"),  # type: ignore[arg-type]
        ],
        loc="upper right",
        fontsize=7,
        frameon=False,
        ncol=2,
        bbox_to_anchor=(1.0, 1.35),
    )


def plot_transform(
    before: Tensor,
    after: Tensor,
    path: str | os.PathLike[str] | None = None,
    *,
    frame_ms: float = 10.0,
    count: int = 8,
    title: str = "",
    upscale: int = 2,
) -> Any:
    """A labelled before/after figure of one sequence: the frames the transform acts on.

    Row "before" and row "after" share one colour scale (so added or removed events show);
    each column is titled with its frame's time window; the legend names the polarity
    colours. Needs matplotlib (the ``plot`` extra).

    Args:
        before, after: one sequence ``(T, 2, H, W)`` each.
        path: where to write the PNG (optional).
        frame_ms: frame length, for the times.
        count: frames shown, those changed most (:func:`acting_frames`).
        title: the figure's title (e.g. the method's name).
        upscale: integer magnification of the frames.

    Returns:
        The matplotlib figure (closed if ``path`` was given).
    """
    plt = _pyplot()
    frames = acting_frames(before, after, count)
    pair = torch.stack([before.detach().cpu().double(), after.detach().cpu().double()])
    vmax = float(pair.amax()) if pair.numel() else 1.0
    rgb = frames_to_rgb(pair[:, frames], vmax=vmax)  # (2, k, 3, H, W)
    if upscale > 1:
        rgb = rgb.repeat_interleave(upscale, -2).repeat_interleave(upscale, -1)
    k, (h, w) = len(frames), rgb.shape[-2:]
    padding = 2
    image = _torchvision_utils().make_grid(rgb.flatten(0, 1), nrow=k, padding=padding, pad_value=128)
    fig, ax = plt.subplots(figsize=(1.2 * k + 1.2, 3.0))
    ax.imshow(image.permute(1, 2, 0).numpy())
    ax.set_xticks([padding + (w + padding) * c + w / 2 for c in range(k)])
    ax.set_xticklabels([f"{int(t) * frame_ms:g}–{(int(t) + 1) * frame_ms:g} ms" for t in frames], fontsize=7)
    ax.set_yticks([padding + (h + padding) * r + h / 2 for r in range(2)])
    ax.set_yticklabels(["before", "after"], fontsize=9)
    _legend(ax)
    ax.set_title(title or "transform", fontsize=10, loc="left", pad=22)
    ax.set_xlabel("the frames the transform changes most; before and after share one colour scale", fontsize=7)
    fig.subplots_adjust(left=0.08, right=0.98, top=0.8, bottom=0.2)
    return _saved(fig, path, plt, dpi=110)


def plot_scene(
    train: Tensor,
    deploy: Tensor,
    path: str | os.PathLike[str] | None = None,
    *,
    title: str = "",
    gaps: Sequence[str] = (),
    frame_ms: float = 10.0,
    rows: int = 2,
    every: int = 4,
    upscale: int = 1,
) -> Any:
    """A scene at a glance: training recordings above deployment recordings, and what differs.

    Left: ``rows`` training and ``rows`` deployment recordings (every ``every``-th frame,
    labelled by session and time). Right: the mean contact-event rate per frame of each
    session (timing gaps show as shifted curves), and histograms over all given recordings of
    the contact width, the contact angle and the background rate
    (:func:`event_transforms.inference.sequence_statistics`): size, orientation and noise
    gaps show as shifted histograms. The title names the gaps. Needs matplotlib.

    Args:
        train, deploy: recordings ``(N, T, 2, H, W)`` of each session (N ≥ ``rows``).
        path: where to write the PNG (optional).
        title: the figure's title (e.g. the scene's name and description).
        gaps: the scene's gaps, named in the title.
        frame_ms: frame length.
        rows: recordings of each session drawn as frames.
        every: show every n-th frame.
        upscale: integer magnification of the frames.

    Returns:
        The matplotlib figure (closed if ``path`` was given).
    """
    from .inference import sequence_statistics

    plt = _pyplot()
    check_frames(train, "train")
    check_frames(deploy, "deploy")
    if isinstance(rows, bool) or not isinstance(rows, int) or rows < 1:
        raise ValueError(f"rows must be a positive integer, got {rows!r}")
    if train.dim() != 5 or deploy.dim() != 5 or rows > min(train.shape[0], deploy.shape[0]):
        raise ValueError(
            f"rows={rows} asks for more recordings than the sessions hold (train {tuple(train.shape)}, deploy "
            f"{tuple(deploy.shape)}): pass (N, T, 2, H, W) with N >= rows"
        )
    shown = torch.cat([train[:rows], deploy[:rows]]).detach().cpu().double()[:, ::every]
    k, (h, w) = shown.shape[1], shown.shape[-2:]
    padding = 2
    image = make_event_grid(shown, nrow=k, padding=padding, upscale=upscale)  # one image: cheap to draw
    fig = plt.figure(figsize=(0.75 * k + 6.5, 0.8 * 2 * rows + 1.6))
    grid = fig.add_gridspec(2, 3, width_ratios=[0.75 * k, 3.0, 3.0], wspace=0.35, hspace=0.55)
    ax = fig.add_subplot(grid[:, 0])
    ax.imshow(image.permute(1, 2, 0).numpy())
    step_x, step_y = w * upscale + padding, h * upscale + padding
    ax.set_xticks([padding + step_x * c + w * upscale / 2 for c in range(k)])
    ax.set_xticklabels([f"{c * every * frame_ms:g}" for c in range(k)], fontsize=7)
    ax.set_xlabel("frame start (ms)", fontsize=8)
    ax.set_yticks([padding + step_y * r + h * upscale / 2 for r in range(2 * rows)])
    ax.set_yticklabels([("training" if r < rows else "deployment") + f" {r % rows + 1}" for r in range(2 * rows)], fontsize=8)
    ax.axhline(padding / 2 + step_y * rows, color="black", linewidth=1.5)
    _legend(ax)
    colours = {"training": "tab:gray", "deployment": "tab:purple"}
    stats = {name: sequence_statistics(x.detach().cpu()) for name, x in (("training", train), ("deployment", deploy))}
    times = (torch.arange(train.shape[1]) + 0.5) * frame_ms
    ax = fig.add_subplot(grid[0, 1])
    ax.tick_params(labelsize=7)
    for name, x in (("training", train), ("deployment", deploy)):
        ax.plot(times, x.detach().double().sum((2, 3, 4)).mean(0), color=colours[name], label=name)
    ax.set_xlabel("time (ms)", fontsize=8)
    ax.set_ylabel("events per frame (mean)", fontsize=8)
    ax.set_title("event rate: timing", fontsize=8)
    ax.legend(fontsize=7, frameon=False)
    panels = [
        ("width_px", "contact width (px): size", grid[1, 1]),
        ("angle_deg", "contact angle (°): orientation", grid[0, 2]),
        ("background", "background (events/px/frame): noise", grid[1, 2]),
    ]
    for key, label, cell in panels:
        ax = fig.add_subplot(cell)
        values = torch.cat([stats["training"][key], stats["deployment"][key]])
        low, high = float(values.min()), float(values.max())
        bins = torch.linspace(low, high if high > low else low + 1, 16).numpy()
        for name in ("training", "deployment"):
            ax.hist(stats[name][key].numpy(), bins=bins, alpha=0.55, color=colours[name], label=name)
        ax.set_title(label, fontsize=8)
        ax.tick_params(labelsize=7)
    named = ", ".join(gaps) if gaps else "none (control)"
    fig.suptitle(f"{title}\ngaps: {named}", fontsize=9, x=0.01, ha="left")
    fig.subplots_adjust(left=0.08, right=0.98, top=0.8, bottom=0.12)
    return _saved(fig, path, plt, dpi=100)


def _saved(fig: Any, path: str | os.PathLike[str] | None, plt: Any, *, dpi: int) -> Any:
    """Write ``fig`` to ``path`` (folders made) and close it; the figure either way.

    ``path`` is the file written, exactly: an existing folder or a name without a suffix
    (which matplotlib would complete to ``<path>.png`` beside it) is refused.
    """
    if path is not None:
        if Path(path).is_dir() or not Path(path).suffix:
            plt.close(fig)
            raise ValueError(f"path must name an image file (e.g. figure.png), got {str(path)!r}")
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=dpi)
        plt.close(fig)
    return fig
