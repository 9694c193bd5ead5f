"""``EmulateEvents``: a video in, events out, with the camera drawn per sample (a DVS emulator as a module)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from torch import Tensor

from .._validation import check_pair, check_seed
from ..events.batch import EventBatch
from ..functional.emulate import EMULATE_EVENTS_SPEC, emulate_events
from ._tree import check_tree
from .base import EventTransform, Param, Params, seeds, uniform

__all__ = ["EmulateEvents"]

_RANGES = ("threshold_on", "mismatch", "refractory_us", "noise_hz", "leak_hz", "hot_pixel_fraction", "hot_pixel_hz")


class EmulateEvents(EventTransform):
    """Emulate a DVS camera on luminance (or RGB) frames, the camera's parameters drawn per sample.

    :func:`~event_transforms.functional.emulate_events` as a module: each sample gets its own
    camera, contrast thresholds, mismatch, refractory period and noise drawn uniformly from
    the given ranges (a number is a fixed value). Drawing the contrast threshold per
    sequence is itself an augmentation: it varies what differs between two event cameras
    (Stoffregen et al., "Reducing the sim-to-real gap for event cameras", ECCV 2020, drew the
    thresholds per training sequence). Between two frames the log intensity is interpolated
    linearly (ESIM), so timing finer than a frame is an interpolation, not a measurement.

    The params tree holds one value per sample of every camera argument and two seeds
    (``seed``: leak phases and noise events; ``camera_seed``: the per-pixel thresholds,
    noise rates and hot pixels); ``module(frames, params=tree)`` replays a draw exactly,
    and a sample alone equals the sample in a batch. Unlike the frame transforms it
    changes the input's kind (:attr:`~EventTransform.takes_video`), so it stands alone, first in a
    :class:`~event_transforms.Compose` (event transforms and
    :class:`~event_transforms.EventsToFrames` after it), or in a :class:`~event_transforms.OneOf`
    of cameras; :class:`~event_transforms.RandomApply` refuses it (some samples would stay a
    video). It takes no probability ``p`` and has no label hook.

    Args:
        fps: the frames' rate (frames at ``k / fps`` s), or ``None`` and give
            ``frame_times_us`` to each call.
        threshold: ON threshold range ``(min, max)`` or a number (log units, > 0).
        threshold_off: OFF threshold range, or ``None``: the ON draw (a symmetric camera).
        mismatch: relative standard deviation of the per-pixel thresholds, range or number.
        refractory_us: refractory period in microseconds, range or number.
        noise_hz: geometric-mean shot-noise rate per pixel, range or number.
        leak_hz: leak-event rate, range or number.
        hot_pixel_fraction: fraction of hot pixels, range or number.
        hot_pixel_hz: geometric-mean rate of a hot pixel, range or number.
        camera_seed: one camera for every sample (its seed), or ``None``: a camera per sample.
        channel: ``None`` for luminance frames; ``"mean"``, ``"luma"`` or a channel index for
            RGB frames (:func:`~event_transforms.functional.to_luminance`).
        knee_dn: the lin-log knee in digital numbers.
        chunk_frames: frames read at a time (``None``: automatic).

    Shape:
        - input: ``(T, H, W)`` or ``(B, T, H, W)`` luminance (with ``channel``: ``(T, 3, H, W)``
          or ``(B, T, 3, H, W)``), uint8 or float.
        - output: an :class:`~event_transforms.EventBatch` of B (or 1) streams, sensor ``(H, W)``.

    Example:
        >>> import event_transforms as et
        >>> emulate = et.EmulateEvents(fps=30.0, threshold=(0.15, 0.3), mismatch=0.03)
        >>> video = torch.linspace(0.2, 0.8, 8).view(1, 8, 1, 1).expand(2, 8, 6, 5)
        >>> params = emulate.make_params(video.shape, generator=torch.Generator().manual_seed(0))
        >>> sorted(params)[:3], params["threshold_on"].shape
        (['camera_seed', 'hot_pixel_fraction', 'hot_pixel_hz'], torch.Size([2]))
        >>> events = emulate(video, params=params)
        >>> events.lengths == emulate(video, params=params).lengths  # replayed
        True
    """

    def __init__(
        self,
        fps: float | None = None,
        *,
        threshold: float | Sequence[float] = (0.15, 0.3),
        threshold_off: float | Sequence[float] | None = None,
        mismatch: float | Sequence[float] = 0.03,
        refractory_us: float | Sequence[float] = 0.0,
        noise_hz: float | Sequence[float] = 0.0,
        leak_hz: float | Sequence[float] = 0.0,
        hot_pixel_fraction: float | Sequence[float] = 0.0,
        hot_pixel_hz: float | Sequence[float] = 100.0,
        camera_seed: int | None = None,
        channel: str | int | None = None,
        knee_dn: float = 20.0,
        chunk_frames: int | None = None,
    ) -> None:
        super().__init__()
        self.fps = fps
        self.ranges: dict[str, tuple[float, float]] = {}
        values = dict(threshold_on=threshold, mismatch=mismatch, refractory_us=refractory_us, noise_hz=noise_hz,
                      leak_hz=leak_hz, hot_pixel_fraction=hot_pixel_fraction, hot_pixel_hz=hot_pixel_hz)
        for key in _RANGES:
            spec = EMULATE_EVENTS_SPEC[key]
            low = 0.0 if spec.low is None else spec.low
            high = float("inf") if spec.high is None else spec.high
            name = "threshold" if key == "threshold_on" else key
            pair = check_pair(values[key], name, low=low, high=high, single=True)
            if spec.low_open and pair[0] <= low:
                raise ValueError(f"{name} must be > {low}, got {values[key]!r}")
            self.ranges[key] = pair
        self.threshold_off = None if threshold_off is None else check_pair(threshold_off, "threshold_off", low=0.0,
                                                                           single=True)
        if self.threshold_off is not None and self.threshold_off[0] <= 0:
            raise ValueError(f"threshold_off must be > 0, got {threshold_off!r}")
        self.camera_seed = None if camera_seed is None else check_seed(camera_seed, "camera_seed")
        self.channel = channel
        self.knee_dn = knee_dn
        self.chunk_frames = chunk_frames
        if fps is not None:
            emulate_events(torch.zeros(1, 1, 1), fps=fps, knee_dn=knee_dn, channel=None, seed=0)  # checks fps, knee
        if channel is not None:
            emulate_events(torch.zeros(1, 3, 1, 1), fps=1.0, channel=channel, seed=0)  # checks channel

    def params_spec(self, shape: torch.Size) -> dict[str, Param]:
        return dict(EMULATE_EVENTS_SPEC)

    def sample_params(self, shape: torch.Size, *, generator: torch.Generator | None = None, metadata: Any = None) -> Params:
        batch = shape[0]
        params: Params = {key: uniform(*self.ranges[key], batch, generator) for key in _RANGES}
        params["threshold_off"] = (params["threshold_on"].clone() if self.threshold_off is None
                                   else uniform(*self.threshold_off, batch, generator))
        params["seed"] = seeds(batch, generator)
        params["camera_seed"] = (seeds(batch, generator) if self.camera_seed is None
                                 else torch.full((batch,), self.camera_seed, dtype=torch.int64))
        return params

    @property
    def takes_video(self) -> bool:
        return True

    def video_shape(self, shape: Sequence[int]) -> torch.Size:
        """The batched video shape ``(B, T, H, W)`` (``(B, T, 3, H, W)`` with ``channel``) of ``shape``."""
        rank = 5 if self.channel is not None else 4
        dims = tuple(int(s) for s in shape)
        if len(dims) == rank - 1:
            dims = (1, *dims)
        if len(dims) != rank or any(s < 0 for s in dims):
            kind = "(B, T, 3, H, W)" if self.channel is not None else "(B, T, H, W)"
            raise ValueError(f"EmulateEvents: expected a video shape {kind}, got {tuple(shape)!r}")
        return torch.Size(dims)

    def output_shape(self, shape: torch.Size) -> torch.Size:
        """The frame shape the events' transforms draw for: ``(B, 1, 2, H, W)`` (the events have no frame grid)."""
        return torch.Size((shape[0], 1, 2, shape[-2], shape[-1]))

    def forward(  # type: ignore[override]  # adds frame_times_us to the base call
        self, frames: Tensor, *rest: Any, frame_times_us: Tensor | Sequence[float] | None = None,
        generator: torch.Generator | None = None, params: Params | None = None, metadata: Any = None,
    ) -> Any:
        """Emulate the events of ``frames`` (see the class docstring); ``params`` replays a draw.

        The base class's call (a video in, an :class:`~event_transforms.EventBatch` out, other
        inputs passed through), plus ``frame_times_us`` for a module made with ``fps=None``:
        ``(T,)`` or ``(B, T)`` frame times in microseconds, for this call.
        """
        if frame_times_us is None:
            if self.fps is None:
                raise TypeError("EmulateEvents(fps=None) needs frame_times_us= at each call")
            return super().forward(frames, *rest, generator=generator, params=params, metadata=metadata)
        if not isinstance(frames, Tensor):
            raise TypeError(f"EmulateEvents takes a video as a torch.Tensor, got {type(frames).__name__}")
        shape = self.video_shape(frames.shape)
        if params is None:
            params = self.make_params(shape, generator=generator, metadata=metadata)
        else:
            params = check_tree(self, params, shape)
        events = emulate_events(
            frames, frame_times_us=frame_times_us, channel=self.channel, knee_dn=self.knee_dn,
            chunk_frames=self.chunk_frames, **{key: params[key] for key in EMULATE_EVENTS_SPEC},
        )
        return (events, *rest) if rest else events

    def apply_transform(self, inputs: Tensor | EventBatch, params: Params) -> Tensor | EventBatch:
        if isinstance(inputs, EventBatch):
            raise TypeError("EmulateEvents takes a video, not an EventBatch: put it first in the pipeline")
        if self.fps is None:
            raise TypeError("EmulateEvents(fps=None) in a container: give the module fps= (frame times "
                            "per call need the direct call, emulate(frames, frame_times_us=...))")
        return emulate_events(
            inputs, fps=self.fps, channel=self.channel, knee_dn=self.knee_dn,
            chunk_frames=self.chunk_frames, **{key: params[key] for key in EMULATE_EVENTS_SPEC},
        )

    def _settings(self) -> str:
        parts = [f"fps={self.fps}"]
        for key, pair in self.ranges.items():
            parts.append(f"{'threshold' if key == 'threshold_on' else key}={pair[0] if pair[0] == pair[1] else pair}")
        if self.threshold_off is not None:
            parts.append(f"threshold_off={self.threshold_off}")
        if self.camera_seed is not None:
            parts.append(f"camera_seed={self.camera_seed}")
        if self.channel is not None:
            parts.append(f"channel={self.channel!r}")
        return ", ".join(parts)
