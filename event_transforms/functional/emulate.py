"""Frames to events: a batched DVS emulator on the frames' device (the model of ESIM and v2e).

Each pixel of a dynamic vision sensor remembers the log intensity at its last event (its
*reference*) and emits an ON (OFF) event whenever the log intensity has risen (fallen) by
its contrast threshold since then; the reference then moves by that threshold. This is the
model of the published DVS emulators, ESIM (Rebecq, Gehrig & Scaramuzza, CoRL 2018) and v2e
(Hu, Liu & Delbruck, CVPR Workshops 2021). Its
parts, each a per-sample argument:

- **Lin-log response** (v2e's): the luminance in digital numbers ``x`` (uint8 frames as
  they are, float frames ``255 ·`` a luminance in [0, 1]) gives ``log(x)`` above
  ``knee_dn`` (20 DN) and the linear ramp ``x · log(knee_dn) / knee_dn`` below it, so a
  dark pixel is not infinitely sensitive. The level is rounded to ``2**-20`` so that last-bit differences of ``log`` between math
  libraries rarely change an event.
- **Per-pixel thresholds with mismatch**: ``θ · max(1 + σ z, 0.1)`` for ON and OFF, ``z``
  standard normal per pixel (v2e's ``pos_thres``/``neg_thres``/``sigma_thres``).
- **Refractory period** ``R``: after an event a pixel is blind for ``R`` microseconds and its
  reference follows the light meanwhile (the reset switch of a real pixel), so the change
  during that time is lost; under a steady slope ``s`` (log units per µs) events come
  ``θ / s + R`` apart.
- **Leak**: the reference decays by ``θ_ON · leak_hz`` per second, so a pixel under constant
  light emits an ON event every ``1 / leak_hz`` s (plus ``R``), at a random phase per pixel
  and recording (v2e's random initial reference; drawn only when ``leak_hz > 0``).
- **Shot noise and hot pixels**: Poisson events independent of the light, per pixel at a
  rate ``noise_hz · noise_spread**(2u - 1)`` (log-uniform around ``noise_hz``; v2e's
  ``shot_noise_rate_hz``), plus, for a fraction ``hot_pixel_fraction`` of the pixels (each
  pixel independently), ``hot_pixel_hz · hot_pixel_spread**(2u - 1)``; ON with probability
  ``noise_on_fraction``.

**Timing.** Between two frames the log intensity is interpolated linearly (ESIM's rule), and
the reference's leak is linear too, so each crossing has a closed-form time inside the
frame interval ``[t_k, t_{k+1}]``. Timing finer than a frame is therefore an interpolation,
not a measurement: at 30 frames/s every event of one interval comes from the same two
frames, and a bin shorter than the frame interval shows the interpolation's ramp, not the
scene's. Noise events are uniform in ``[t_0, t_{T-1})``.

**Randomness.** Every random number is a counter-based draw of the library
(:mod:`event_transforms.functional._random`): a pixel's thresholds, noise rate and hot-pixel
state are named by (``camera_seed``, pixel index), the leak phases and the noise events by
(``seed``, pixel or event index). So a sample alone equals the sample in any batch, the same
numbers come on the CPU and CUDA, and recordings of one camera share ``camera_seed``.

**Memory and speed.** The frames are read ``chunk_frames`` at a time (a few host reads per
chunk: the fired pixels, the still ones; none per frame); the state is five ``(B, H·W)``
float32 arrays. Work is about 40 elementwise operations per pixel and frame, in float32, on
the pixels that can change in the chunk only: a pixel whose level stays the same in every
sample, without leak or blind time, and whose state gives no event is left out (exactly: it
would emit nothing and keep its state). Each noise event's pixel comes from a bucket table of
the cumulative rates (the index ``searchsorted`` gives, without a binary search of the row).

The parts are public for callers that render some pixels only: :func:`threshold_crossings`
(the crossings of any set of pixels' levels), :func:`camera_pixels` (a camera's per-pixel
draws) and :func:`noise_events` (shot noise and hot pixels).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import Tensor

from .._params import SEED, Param, check_args
from .._validation import as_number, check_positive, describe, read_host
from ..events.batch import EventBatch
from ._random import draw_seeds, poisson_counts, sample_keys, search_cumulative, sub_normal_pair, sub_uniform, sub_uniform32

__all__ = ["emulate_events", "threshold_crossings", "camera_pixels", "noise_events", "to_luminance", "LOG_QUANTUM"]

#: The camera's per-sample arguments (one declaration for the function and the module).
EMULATE_EVENTS_SPEC: dict[str, Param] = {
    "threshold_on": Param("float", low=0.0, low_open=True),
    "threshold_off": Param("float", low=0.0, low_open=True),
    "mismatch": Param("float", low=0.0, high=1.0),
    "refractory_us": Param("float", low=0.0),
    "noise_hz": Param("float", low=0.0),
    "leak_hz": Param("float", low=0.0),
    "hot_pixel_fraction": Param("float", low=0.0, high=1.0),
    "hot_pixel_hz": Param("float", low=0.0),
    "seed": SEED,
    "camera_seed": SEED,
}

#: Resolution of the log intensity before thresholding (machine independence).
LOG_QUANTUM = 2.0**-20
#: Luma weights of ITU-R BT.601 (the ``channel="luma"`` conversion).
_LUMA = (0.299, 0.587, 0.114)
_DTYPES = (torch.uint8, torch.float16, torch.bfloat16, torch.float32, torch.float64)
#: Elements of the float32 work arrays per chunk (frames times pixels times batch).
_CHUNK_ELEMENTS = 1 << 20

# purposes of the counter-based draws (per pixel: camera_seed; per recording: seed)
_MISMATCH, _NOISE_RATE, _HOT, _HOT_RATE = 1, 4, 5, 6
_PHASE, _NOISE_PIXEL, _NOISE_TIME, _NOISE_POLARITY, _NOISE_COUNT = 1, 2, 3, 4, 7


def to_luminance(frames: Tensor, channel: str | int) -> Tensor:
    """RGB frames ``(..., 3, H, W)`` to luminance ``(..., H, W)`` by a stated rule.

    Args:
        frames: RGB frames, uint8 or float, the colour axis third from last.
        channel: ``"mean"`` (the mean of R, G, B), ``"luma"`` (ITU-R BT.601:
            0.299 R + 0.587 G + 0.114 B) or an index 0, 1, 2 (one colour channel).

    Shape:
        - frames: ``(..., 3, H, W)``; output: ``(..., H, W)`` float32 (uint8 input stays in
          digital numbers, 0-255; float input keeps its scale).

    Example:
        >>> rgb = torch.tensor([30, 60, 90], dtype=torch.uint8).view(3, 1, 1)
        >>> to_luminance(rgb, "mean").item(), to_luminance(rgb, 0).item(), round(to_luminance(rgb, "luma").item(), 2)
        (60.0, 30.0, 54.45)
    """
    if not isinstance(frames, Tensor) or frames.dim() < 3 or frames.shape[-3] != 3:
        shown = tuple(frames.shape) if isinstance(frames, Tensor) else type(frames).__name__
        raise ValueError(f"frames: expected RGB frames (..., 3, H, W) with channel={channel!r}, got {shown}")
    work = frames.to(torch.float32)
    if isinstance(channel, bool) or not isinstance(channel, (str, int)):
        raise TypeError(f"channel must be 'mean', 'luma' or 0, 1, 2, got {channel!r}")
    if channel == "mean":
        return work.mean(dim=-3)
    if channel == "luma":
        weights = torch.tensor(_LUMA, dtype=torch.float32, device=frames.device).view(3, 1, 1)
        return (work * weights).sum(dim=-3)
    if isinstance(channel, int) and 0 <= channel <= 2:
        return work.select(-3, channel)
    raise ValueError(f"channel must be 'mean', 'luma' or 0, 1, 2, got {channel!r}")


def _frame_times(batch: int, steps: int, fps: float | None, frame_times_us: object, device: torch.device) -> Tensor:
    """(B, T) float64 frame times in microseconds on ``device``, checked increasing."""
    if (fps is None) == (frame_times_us is None):
        raise TypeError(f"emulate_events needs exactly one of fps= or frame_times_us=, got fps={fps!r} and "
                        f"frame_times_us={describe(frame_times_us)}")
    if fps is not None:
        rate = check_positive(fps, "fps")
        return (torch.arange(steps, dtype=torch.float64) * (1e6 / rate)).expand(batch, steps).to(device)
    if not isinstance(frame_times_us, (Tensor, Sequence)) or isinstance(frame_times_us, (str, bytes)):
        raise TypeError(f"frame_times_us must be a (T,) or (B, T) tensor or sequence, got {describe(frame_times_us)}")
    times = torch.as_tensor(frame_times_us).detach().to(torch.float64).cpu()
    if times.dim() == 1:
        times = times.expand(batch, -1)
    if times.dim() != 2 or tuple(times.shape) != (batch, steps):
        raise ValueError(f"frame_times_us must have shape ({steps},) or ({batch}, {steps}) to match the frames, "
                         f"got {describe(frame_times_us)}")
    if times.numel() and not bool(times.isfinite().all()):
        raise ValueError(f"frame_times_us must be finite, got {describe(frame_times_us)}")
    if steps > 1 and not bool((times.diff(dim=1) > 0).all()):
        raise ValueError(f"frame_times_us must increase strictly along T, got {describe(frame_times_us)}")
    return times.to(device)


def _levels(frames: Tensor, knee_dn: float, digital: bool) -> Tensor:
    """Quantized lin-log levels (float32) of luminance frames (``digital``: in DN; else 255 · value)."""
    x = frames.to(torch.float32)
    if not digital:
        x = x * 255.0
    log_knee = math.log(knee_dn)
    level = torch.where(x > knee_dn, x.clamp_min(knee_dn).log(), x * (log_knee / knee_dn))
    return level.mul_(1.0 / LOG_QUANTUM).round_().mul_(LOG_QUANTUM)


def _camera(keys: Tensor, pixels: int, args: dict[str, Tensor], noise_spread: float, hot_spread: float,
            device: torch.device) -> tuple[Tensor, Tensor, Tensor]:
    """Per-pixel ON/OFF thresholds and noise rates (Hz), (B, P) each, from the camera keys."""
    index = torch.arange(pixels, dtype=torch.int32, device=device).unsqueeze(0)
    key = keys.unsqueeze(1)
    mismatch = args["mismatch"].to(device=device, dtype=torch.float32).unsqueeze(1)
    z_on, z_off = sub_normal_pair(key, index, _MISMATCH)
    on = args["threshold_on"].to(device=device, dtype=torch.float32).unsqueeze(1) * (1.0 + mismatch * z_on).clamp_min(0.1)
    off = args["threshold_off"].to(device=device, dtype=torch.float32).unsqueeze(1) * (1.0 + mismatch * z_off).clamp_min(0.1)
    noise = args["noise_hz"].to(device).unsqueeze(1) * torch.exp(
        (2.0 * sub_uniform(key, index, _NOISE_RATE) - 1.0) * math.log(noise_spread))
    hot = sub_uniform(key, index, _HOT) < args["hot_pixel_fraction"].to(device).unsqueeze(1)
    hot_rate = args["hot_pixel_hz"].to(device).unsqueeze(1) * torch.exp(
        (2.0 * sub_uniform(key, index, _HOT_RATE) - 1.0) * math.log(hot_spread))
    return on, off, noise + torch.where(hot, hot_rate, 0.0)


def _noise_events(seeds: Tensor, keys: Tensor, rates: Tensor, start: Tensor, duration: Tensor,
                  on_fraction: float) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Shot noise and hot pixels: (sample, pixel, t_us, p) of every noise event, unsorted.

    Each sample's total is Poisson(Σ rates · duration) (one counter-based inversion per
    sample); each event's pixel is drawn in proportion to the rates, its time uniform."""
    device = rates.device
    batch, pixels = rates.shape
    total = rates.sum(1) * (duration * 1e-6)
    counts = poisson_counts(seeds, total, _NOISE_COUNT)
    lengths = read_host(counts)
    n = sum(lengths)
    if n == 0 or pixels == 0:
        empty = torch.zeros(0, dtype=torch.int64, device=device)
        return empty, empty, empty.to(torch.float64), empty.to(torch.int8)
    on_device = torch.tensor(lengths, dtype=torch.int64, device=device)
    sample = torch.repeat_interleave(torch.arange(batch, device=device), on_device, output_size=n)
    first = on_device.cumsum(0) - on_device
    within = torch.arange(n, device=device) - first[sample]
    key = keys[sample]
    cumulative = rates.cumsum(1)
    target = sub_uniform(key, within, _NOISE_PIXEL, bits=53) * cumulative[:, -1][sample]
    pixel = search_cumulative(cumulative, sample, target).clamp_max_(pixels - 1)
    t = start[sample] + sub_uniform(key, within, _NOISE_TIME, bits=53) * duration[sample]
    p = (sub_uniform(key, within, _NOISE_POLARITY) < on_fraction).to(torch.int8)
    return sample, pixel, t, p


def _chunk_events(counts: Tensor, d_start: Tensor, blind: Tensor | None, rate: Tensor, times: Tensor, step0: int,
                  on: Tensor, off: Tensor, refractory: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Expand a chunk's signed counts (C, B, P) into events (sample, pixel, t_us, p).

    The crossing times are computed for the fired entries only, from the state each step
    started with: the level minus the reference ``d_start``, the blind time spent in the
    interval ``blind`` (``None``: no refractory period) and the slope ``rate``."""
    fired = counts.nonzero()  # one host read per chunk
    device = counts.device
    if fired.shape[0] == 0:
        empty = torch.zeros(0, dtype=torch.int64, device=device)
        return empty, empty, empty.to(torch.float64), empty.to(torch.int8)
    c, b, i = fired.unbind(1)
    signed = counts[c, b, i]
    slope = rate[c, b, i].to(torch.float64)
    rising = signed > 0
    sign = torch.where(rising, 1.0, -1.0).to(torch.float64)
    theta = torch.where(rising, on[b, i], off[b, i]).to(torch.float64)
    speed = slope.abs()
    to_first = theta - sign * d_start[c, b, i].to(torch.float64)
    spacing = theta + speed * refractory[b, 0].to(torch.float64)
    offset = to_first / speed
    if blind is not None:
        offset = offset + blind[c, b, i].to(torch.float64)
    number = signed.abs().to(torch.int64)
    total = int(read_host(number.sum()))
    row = torch.repeat_interleave(torch.arange(fired.shape[0], device=device), number, output_size=total)
    j = torch.arange(total, device=device) - (number.cumsum(0) - number)[row]
    t = times[b[row], c[row] + step0] + offset[row] + j.to(torch.float64) * (spacing / speed)[row]
    return b[row], i[row], t, rising[row].to(torch.int8)


def emulate_events(
    frames: Tensor,
    *,
    fps: float | None = None,
    frame_times_us: Tensor | Sequence[float] | None = None,
    threshold_on: float | Tensor = 0.2,
    threshold_off: float | Tensor | None = None,
    mismatch: float | Tensor = 0.0,
    refractory_us: float | Tensor = 0.0,
    noise_hz: float | Tensor = 0.0,
    leak_hz: float | Tensor = 0.0,
    hot_pixel_fraction: float | Tensor = 0.0,
    hot_pixel_hz: float | Tensor = 100.0,
    seed: int | Tensor | None = None,
    camera_seed: int | Tensor | None = None,
    channel: str | int | None = None,
    knee_dn: float = 20.0,
    noise_spread: float = 10.0,
    hot_pixel_spread: float = 2.0,
    noise_on_fraction: float = 0.5,
    random_reference: bool | None = None,
    chunk_frames: int | None = None,
    generator: torch.Generator | None = None,
) -> EventBatch:
    """Emulate a DVS camera watching luminance frames: the events, as an :class:`EventBatch`.

    See the module docstring for the pixel model, the timing rule (linear interpolation of
    the log intensity between frames: sub-frame timing is an interpolation) and the
    randomness. The camera arguments are a number shared by every sample or a ``(B,)``
    tensor (one camera per sample, as :class:`~event_transforms.EmulateEvents` draws them).

    Args:
        frames: luminance frames, uint8 (digital numbers 0-255) or float (a luminance in
            [0, 1], scaled by 255; values outside are used as they are); with ``channel``,
            RGB frames whose colour axis is third from last.
        fps: frame rate (frames at ``k / fps`` s); or give ``frame_times_us``.
        frame_times_us: ``(T,)`` or ``(B, T)`` frame times in microseconds, strictly increasing.
        threshold_on: ON contrast threshold θ_ON (log units, > 0).
        threshold_off: OFF threshold (``None``: equal to ``threshold_on``).
        mismatch: relative standard deviation σ of the per-pixel thresholds.
        refractory_us: blind time after an event, microseconds.
        noise_hz: geometric-mean per-pixel shot-noise rate (0: none).
        leak_hz: leak-event rate under constant light (0: none).
        hot_pixel_fraction: probability that a pixel is hot.
        hot_pixel_hz: geometric-mean rate of a hot pixel.
        seed: per-recording seed(s) (leak phases, noise events); ``None``: drawn from ``generator``.
        camera_seed: per-camera seed(s) (thresholds, noise rates, hot pixels); ``None``: ``seed``.
        channel: ``None`` for luminance frames, or the RGB conversion (:func:`to_luminance`):
            ``"mean"``, ``"luma"`` or a channel index.
        knee_dn: the lin-log knee in digital numbers (> 0).
        noise_spread: per-pixel noise rates lie in ``[noise_hz / spread, noise_hz · spread]``.
        hot_pixel_spread: likewise for the hot pixels' rates.
        noise_on_fraction: probability that a noise event is ON.
        random_reference: each pixel's reference starts a uniform random fraction of its ON
            threshold below the first frame's level (v2e's random initial reference); ``None``:
            where ``leak_hz > 0`` (so a constant scene leaks at a random phase), ``False``: never
            (a reset camera's first leak event comes after ``1 / leak_hz``).
        chunk_frames: frames read at a time (``None``: about 1 M pixel values a chunk).
        generator: draws ``seed`` when it is ``None`` (torch's global RNG for ``None``).

    Returns:
        An :class:`EventBatch` of B streams on the frames' device, sensor ``(H, W)``, each
        sorted by time (ties by pixel), timestamps int64 microseconds on the frames' clock.

    Shape:
        - frames: ``(T, H, W)`` or ``(B, T, H, W)``; with ``channel``, ``(T, 3, H, W)`` or
          ``(B, T, 3, H, W)``.
        - output: an ``EventBatch`` of B (or 1) streams.

    Raises:
        TypeError: frames not a tensor or of an unsupported dtype, neither or both of
            ``fps``/``frame_times_us``.
        ValueError: a wrong shape, a camera argument out of range, frame times not increasing.

    Example:
        >>> ramp = torch.linspace(0.2, 0.6, 5).view(5, 1, 1).expand(5, 2, 3)  # one rising scene
        >>> events = emulate_events(ramp, fps=30.0, threshold_on=0.25, seed=0)
        >>> events.lengths, sorted(set(events.p.tolist()))  # log(0.6 / 0.2) = 1.10: 4 ON events per pixel
        ([24], [1])
        >>> bool((events.t <= 4 * 1e6 / 30).all())
        True
    """
    if not isinstance(frames, Tensor):
        raise TypeError(f"frames must be a torch.Tensor, got {type(frames).__name__}")
    if frames.dtype not in _DTYPES:
        raise TypeError(f"frames must be uint8 or float (float16, bfloat16, float32, float64), got {frames.dtype}")
    if channel is None:
        if frames.dim() not in (3, 4):
            raise ValueError(f"frames: expected luminance (T, H, W) or (B, T, H, W) (give channel= for RGB), "
                             f"got {tuple(frames.shape)}")
    elif frames.dim() not in (4, 5) or frames.shape[-3] != 3:
        raise ValueError(f"frames: expected RGB (T, 3, H, W) or (B, T, 3, H, W) with channel={channel!r}, "
                         f"got {tuple(frames.shape)}")
    else:
        to_luminance(frames[..., :0, :0], channel)  # checks channel before any work
    rgb = channel is not None
    video = frames if frames.dim() == (5 if rgb else 4) else frames.unsqueeze(0)
    batch, steps = video.shape[:2]
    height, width = video.shape[-2:]
    if not (1 <= height <= 2**15 - 1 and 1 <= width <= 2**15 - 1):
        raise ValueError(f"frames: H and W must be >= 1 and fit int16 event coordinates, got {(height, width)}")
    knee = check_positive(knee_dn, "knee_dn")
    for name, value in (("noise_spread", noise_spread), ("hot_pixel_spread", hot_pixel_spread)):
        if as_number(value, name) < 1:
            raise ValueError(f"{name} must be >= 1, got {value!r}")
    on_fraction = as_number(noise_on_fraction, "noise_on_fraction", low=0.0, high=1.0)
    if random_reference is not None and not isinstance(random_reference, bool):
        raise TypeError(f"random_reference must be True, False or None, got {random_reference!r}")
    device = frames.device
    times = _frame_times(batch, steps, fps, frame_times_us, device)
    if seed is None:
        seed = draw_seeds(batch, generator).cpu()
    args = check_args(
        "emulate_events", EMULATE_EVENTS_SPEC, batch, threshold_on=threshold_on,
        threshold_off=threshold_on if threshold_off is None else threshold_off, mismatch=mismatch,
        refractory_us=refractory_us, noise_hz=noise_hz, leak_hz=leak_hz, hot_pixel_fraction=hot_pixel_fraction,
        hot_pixel_hz=hot_pixel_hz, seed=seed, camera_seed=seed if camera_seed is None else camera_seed,
    )
    pixels = height * width
    if chunk_frames is None:
        chunk = max(1, _CHUNK_ELEMENTS // max(1, batch * pixels))
    else:
        chunk = check_positive(chunk_frames, "chunk_frames", integer=True)
    if device.type == "meta":
        raise ValueError(f"emulate_events reads the values of the frames, which frames on the meta device do not hold "
                         f"(frames of shape {tuple(frames.shape)}); the number of events depends on them")
    if batch == 0 or steps == 0:
        return _empty(batch, (height, width), device)
    camera_keys = sample_keys(args["camera_seed"], device)
    keys = sample_keys(args["seed"], device)
    on, off, rates = _camera(camera_keys, pixels, args, float(noise_spread), float(hot_pixel_spread), device)
    parts = []
    if steps > 1:
        parts += _signal(video, times, on, off, keys, args, knee, chunk, channel, random_reference)
    duration = times[:, -1] - times[:, 0]
    parts.append(_noise_events(args["seed"], keys, rates, times[:, 0], duration, on_fraction))
    return _assemble(parts, batch, (height, width), device)


def _per_sample(value: float | Tensor, name: str, batch: int, device: torch.device) -> tuple[Tensor, Tensor]:
    """A non-negative number or ``(B,)`` tensor as a ``(B,)`` float64 CPU tensor and a ``(B, 1)`` float32 on ``device``."""
    host = torch.as_tensor(value.detach().cpu() if isinstance(value, Tensor) else value, dtype=torch.float64)
    if host.dim() == 0:
        host = host.expand(batch)
    if tuple(host.shape) != (batch,):
        raise ValueError(f"{name} must be a number or a ({batch},) tensor, got {describe(value)}")
    if not bool(host.isfinite().all()) or bool((host < 0).any()):
        raise ValueError(f"{name} must be finite and >= 0, got {describe(value)}")
    return host, host.to(device=device, dtype=torch.float32).unsqueeze(1)


def _per_pixel(value: float | Tensor, name: str, batch: int, pixels: int, device: torch.device) -> Tensor:
    """A positive threshold: a number, ``(P,)`` or ``(B, P)``, as a ``(B, P)`` float32 tensor on ``device``."""
    tensor = torch.as_tensor(value, dtype=torch.float32, device=device)
    if tensor.dim() > 2 or tuple(tensor.shape) not in ((), (pixels,), (batch, pixels)):
        raise ValueError(f"{name} must be a number, ({pixels},) or ({batch}, {pixels}), got {describe(value)}")
    if tensor.numel() and not bool((tensor > 0).all() & tensor.isfinite().all()):
        raise ValueError(f"{name} must be positive and finite, got {describe(value)}")
    return tensor.expand(batch, pixels)


def threshold_crossings(
    levels: Tensor,
    times_us: Tensor | Sequence[float],
    threshold_on: float | Tensor,
    threshold_off: float | Tensor | None = None,
    *,
    refractory_us: float | Tensor = 0.0,
    leak_hz: float | Tensor = 0.0,
    state: tuple[Tensor, Tensor] | None = None,
) -> tuple[tuple[Tensor, Tensor, Tensor, Tensor], tuple[Tensor, Tensor]]:
    """The DVS pixel model on log levels of any set of pixels: the crossings and their times.

    The core of :func:`emulate_events` (which calls it on every pixel of its frames, chunk by
    chunk), for callers that render the log intensity of some pixels only: between two times
    the level is interpolated linearly and the reference leaks linearly, so each crossing of
    a threshold has a closed-form time; after an event the pixel is blind for
    ``refractory_us`` and its reference follows the level (see the module docstring). Give
    levels already rounded to :data:`LOG_QUANTUM` for machine-independent events. A long
    recording can come in pieces: pass the returned state and the next piece, whose first
    level and time are the previous piece's last.

    Args:
        levels: log intensity (lin-log levels) of P pixels at T times, per sample.
        times_us: the times in microseconds, strictly increasing.
        threshold_on: ON threshold(s), positive: a number, one per pixel, or per sample and pixel.
        threshold_off: OFF threshold(s) (``None``: ``threshold_on``).
        refractory_us: blind time after an event, a number or one per sample.
        leak_hz: leak rate, a number or one per sample (the reference decays by
            ``threshold_on · leak_hz`` per second).
        state: ``(offset, blind_us)`` where the previous piece ended: the level minus the
            reference and the blind time left per pixel (``None``: references at the first
            level, no pixel blind).

    Returns:
        ``((sample, pixel, t_us, p), state)``: int64 sample and pixel indices, float64 times
        (not rounded; inside the interval of their crossing), int8 polarity (1 ON, 0 OFF),
        ordered by interval, then sample, pixel and time; and the state after the last level.

    Shape:
        - levels: ``(B, T, P)`` or ``(T, P)`` (one sample), float.
        - times_us: ``(T,)`` or ``(B, T)``.
        - threshold_on, threshold_off: a number, ``(P,)`` or ``(B, P)``.
        - refractory_us, leak_hz: a number or ``(B,)``.
        - state and the returned state: two ``(B, P)`` float32 tensors.
        - output events: four ``(N,)`` tensors.

    Raises:
        TypeError: levels not a float tensor.
        ValueError: shapes that do not match, times not increasing, a threshold not positive,
            a negative refractory period or leak rate.

    Example:
        >>> levels = torch.tensor([[0.0], [0.5], [1.0]])  # one pixel rising 1.0 in 2048 µs
        >>> (sample, pixel, t, p), state = threshold_crossings(levels, [0.0, 1024.0, 2048.0], 0.25)
        >>> t.tolist(), p.tolist()  # floor(1.0 / 0.25) = 4 ON events, at the interpolated times
        ([512.0, 1024.0, 1536.0, 2048.0], [1, 1, 1, 1])
        >>> (_, _, t, _), _ = threshold_crossings(levels, [0.0, 1024.0, 2048.0], 0.25, refractory_us=600.0)
        >>> t.tolist()  # blind 600 µs after each event: the change meanwhile is lost
        [512.0, 1624.0]
    """
    if not isinstance(levels, Tensor) or not levels.is_floating_point():
        raise TypeError(f"levels must be a float tensor, got {describe(levels)}")
    if levels.dim() not in (2, 3):
        raise ValueError(f"levels must be (T, P) or (B, T, P), got {tuple(levels.shape)}")
    work = (levels if levels.dim() == 3 else levels.unsqueeze(0)).to(torch.float32)
    batch, steps, pixels = work.shape
    device = work.device
    if not isinstance(times_us, (Tensor, Sequence)) or isinstance(times_us, (str, bytes)):
        raise TypeError(f"times_us must be a (T,) or (B, T) tensor or sequence, got {describe(times_us)}")
    times = torch.as_tensor(times_us).detach().to(device=device, dtype=torch.float64)
    if times.dim() == 1:
        times = times.expand(batch, -1)
    if tuple(times.shape) != (batch, steps):
        raise ValueError(f"times_us must be ({steps},) or ({batch}, {steps}) to match levels {tuple(levels.shape)}, "
                         f"got {describe(times_us)}")
    if steps > 1 and not bool((times.diff(dim=1) > 0).all() & times.isfinite().all()):
        raise ValueError(f"times_us must be finite and increase strictly, got {describe(times_us)}")
    on = _per_pixel(threshold_on, "threshold_on", batch, pixels, device)
    off = on if threshold_off is None else _per_pixel(threshold_off, "threshold_off", batch, pixels, device)
    refractory_host, refractory = _per_sample(refractory_us, "refractory_us", batch, device)
    leak_host, leak = _per_sample(leak_hz, "leak_hz", batch, device)
    if state is None:
        d = torch.zeros(batch, pixels, dtype=torch.float32, device=device)
        blind = torch.zeros_like(d)
    else:
        if not (isinstance(state, tuple) and len(state) == 2 and all(isinstance(s, Tensor) for s in state)):
            raise TypeError(f"state must be the (offset, blind_us) pair of tensors returned before, got {describe(state)}")
        if any(tuple(s.shape) != (batch, pixels) for s in state):
            raise ValueError(f"state must be two ({batch}, {pixels}) tensors, got "
                             f"{[tuple(s.shape) for s in state]}")
        d, blind = (s.to(device=device, dtype=torch.float32) for s in state)
    if steps < 2:
        empty = torch.zeros(0, dtype=torch.int64, device=device)
        return (empty, empty, empty.to(torch.float64), empty.to(torch.int8)), (d, blind)
    events, d, blind = _crossings(work, times, on, off, refractory, leak, bool((leak_host > 0).any()),
                                  not bool((refractory_host > 0).any()), d, blind,
                                  leaks_all=bool((leak_host > 0).all()))
    return events, (d, blind)


def camera_pixels(
    pixels: int,
    *,
    camera_seed: int | Tensor,
    threshold_on: float | Tensor = 0.2,
    threshold_off: float | Tensor | None = None,
    mismatch: float | Tensor = 0.0,
    noise_hz: float | Tensor = 0.0,
    hot_pixel_fraction: float | Tensor = 0.0,
    hot_pixel_hz: float | Tensor = 100.0,
    noise_spread: float = 10.0,
    hot_pixel_spread: float = 2.0,
    device: torch.device | str | None = None,
) -> tuple[Tensor, Tensor, Tensor]:
    """A camera's fixed pixel properties, the ones :func:`emulate_events` draws from ``camera_seed``.

    Pixel ``i`` (row-major over ``(H, W)``) of camera ``camera_seed`` gets the same thresholds
    and noise rate here as in :func:`emulate_events` with the same arguments; give them to
    :func:`threshold_crossings` (thresholds of the pixels rendered) and :func:`noise_events`.

    Args:
        pixels: number of pixels P (``H · W``).
        camera_seed: per-camera seed(s); B is its length (1 for a number).
        threshold_on: as in :func:`emulate_events` (a number or ``(B,)``), likewise the next seven.
        threshold_off: OFF threshold (``None``: ``threshold_on``).
        mismatch: relative standard deviation of the thresholds.
        noise_hz: geometric-mean shot-noise rate.
        hot_pixel_fraction: probability that a pixel is hot.
        hot_pixel_hz: geometric-mean rate of a hot pixel.
        noise_spread: noise rates lie in ``[noise_hz / spread, noise_hz · spread]``.
        hot_pixel_spread: likewise for the hot pixels.
        device: where the tensors go (``None``: the CPU).

    Returns:
        ``(threshold_on, threshold_off, rate_hz)``: per-pixel thresholds (float32) and
        noise rates, shot noise plus hot pixels (float64).

    Shape:
        - output: three ``(B, P)`` tensors.

    Example:
        >>> on, off, rate = camera_pixels(6, camera_seed=0, mismatch=0.03, noise_hz=1.0)
        >>> on.shape, bool((rate >= 0.1).all() and (rate <= 10.0).all())
        (torch.Size([1, 6]), True)
    """
    count = check_positive(pixels, "pixels", integer=True)
    batch = camera_seed.numel() if isinstance(camera_seed, Tensor) and camera_seed.dim() > 0 else 1
    spec = {name: EMULATE_EVENTS_SPEC[name] for name in ("threshold_on", "threshold_off", "mismatch", "noise_hz",
                                                         "hot_pixel_fraction", "hot_pixel_hz", "camera_seed")}
    args = check_args("camera_pixels", spec, batch, threshold_on=threshold_on,
                      threshold_off=threshold_on if threshold_off is None else threshold_off, mismatch=mismatch,
                      noise_hz=noise_hz, hot_pixel_fraction=hot_pixel_fraction, hot_pixel_hz=hot_pixel_hz,
                      camera_seed=camera_seed)
    for name, value in (("noise_spread", noise_spread), ("hot_pixel_spread", hot_pixel_spread)):
        if as_number(value, name) < 1:
            raise ValueError(f"{name} must be >= 1, got {value!r}")
    where = torch.device("cpu") if device is None else torch.device(device)
    keys = sample_keys(args["camera_seed"], where)
    return _camera(keys, count, args, float(noise_spread), float(hot_pixel_spread), where)


def noise_events(
    rate_hz: Tensor,
    duration_us: float | Tensor,
    *,
    seed: int | Tensor,
    start_us: float | Tensor = 0.0,
    on_fraction: float = 0.5,
) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Shot noise and hot pixels: Poisson events at per-pixel rates, the draws of :func:`emulate_events`.

    Each sample's number of events is Poisson(Σ rates · duration), each event's pixel is drawn
    in proportion to the rates, its time uniform in ``[start_us, start_us + duration_us)``, ON
    with probability ``on_fraction``; every draw is named by (``seed``, event index), so a
    sample alone equals the sample in a batch.

    Args:
        rate_hz: per-pixel rates (for example :func:`camera_pixels`' third output), >= 0.
        duration_us: the recording's length in microseconds, a number or one per sample.
        seed: per-recording seed(s).
        start_us: the recording's start, a number or one per sample.
        on_fraction: probability that an event is ON.

    Returns:
        ``(sample, pixel, t_us, p)``, unsorted: int64, int64, float64 (not rounded), int8.

    Shape:
        - rate_hz: ``(P,)`` (one sample) or ``(B, P)``; seed, duration_us, start_us: a number or ``(B,)``.
        - output: four ``(N,)`` tensors.

    Example:
        >>> sample, pixel, t, p = noise_events(torch.tensor([[0.0, 1e4]]), 1000.0, seed=0)
        >>> bool((pixel == 1).all()), bool((t < 1000.0).all()), len(t) > 0
        (True, True, True)
    """
    if not isinstance(rate_hz, Tensor) or rate_hz.dim() not in (1, 2):
        raise ValueError(f"rate_hz must be a (P,) or (B, P) tensor, got {describe(rate_hz)}")
    rates = (rate_hz if rate_hz.dim() == 2 else rate_hz.unsqueeze(0)).to(torch.float64)
    if rates.numel() and not bool((rates >= 0).all() & rates.isfinite().all()):
        raise ValueError(f"rate_hz must be finite and >= 0, got {describe(rate_hz)}")
    batch = rates.shape[0]
    device = rates.device
    fraction = as_number(on_fraction, "on_fraction", low=0.0, high=1.0)
    args = check_args("noise_events", {"seed": SEED}, batch, seed=seed)
    duration, _ = _per_sample(duration_us, "duration_us", batch, device)
    start = torch.as_tensor(start_us.detach().cpu() if isinstance(start_us, Tensor) else start_us,
                            dtype=torch.float64).expand(batch)
    if not bool(start.isfinite().all()):
        raise ValueError(f"start_us must be finite, got {describe(start_us)}")
    keys = sample_keys(args["seed"], device)
    return _noise_events(args["seed"], keys, rates, start.to(device), duration.to(device), fraction)


def _signal(video: Tensor, times: Tensor, on: Tensor, off: Tensor, keys: Tensor, args: dict[str, Tensor],
            knee: float, chunk: int, channel: str | int | None, random_reference: bool | None
            ) -> list[tuple[Tensor, Tensor, Tensor, Tensor]]:
    """The threshold crossings of every pixel, ``chunk`` frame intervals at a time (:func:`_crossings`)."""
    device = video.device
    batch, steps = video.shape[:2]
    pixels = on.shape[1]

    def levels(a: int, b: int) -> Tensor:  # (B, b - a, P) levels of frames a .. b - 1
        part = video[:, a:b]
        if channel is not None:
            part = to_luminance(part, channel)
        return _levels(part, knee, video.dtype == torch.uint8).reshape(batch, b - a, pixels)

    leak_hz = args["leak_hz"].to(device=device, dtype=torch.float32).unsqueeze(1)
    leaks = bool((args["leak_hz"] > 0).any())  # CPU arguments: no device read
    leaks_all = bool((args["leak_hz"] > 0).all())
    ideal = not bool((args["refractory_us"] > 0).any())
    refractory = args["refractory_us"].to(device=device, dtype=torch.float32).unsqueeze(1)
    index = torch.arange(pixels, dtype=torch.int32, device=device).unsqueeze(0)
    random = (leak_hz > 0) if random_reference is None else torch.full_like(leak_hz, float(random_reference)).bool()
    d = torch.where(random, sub_uniform32(keys.unsqueeze(1), index, _PHASE), 0.0).mul_(on)  # v2e's random reference
    blind = torch.zeros_like(d)
    parts = []
    previous = levels(0, 1)
    for start in range(0, steps - 1, chunk):
        stop = min(steps - 1, start + chunk)
        block = torch.cat([previous, levels(start + 1, stop + 1)], dim=1)
        part, d, blind = _crossings(block, times[:, start : stop + 1], on, off, refractory, leak_hz, leaks, ideal,
                                    d, blind, leaks_all=leaks_all)
        parts.append(part)
        previous = block[:, -1:]
    return parts


def _crossings(levels: Tensor, times: Tensor, on: Tensor, off: Tensor, refractory: Tensor, leak_hz: Tensor,
               leaks: bool, ideal: bool, d: Tensor, blind: Tensor, *, leaks_all: bool
               ) -> tuple[tuple[Tensor, Tensor, Tensor, Tensor], Tensor, Tensor]:
    """The crossings of levels ``(B, C + 1, P)`` at ``times`` ``(B, C + 1)`` from the state ``(d, blind)``
    (level minus reference, blind time left): the events ``(sample, pixel, t_us, p)`` and the new state.

    ``refractory`` and ``leak_hz`` are ``(B, 1)`` float32; ``leaks`` and ``ideal`` say whether any
    leak rate or refractory period is non-zero, ``leaks_all`` whether every sample leaks (read by
    the caller from its host arguments, no device read here).
    Pixels that provably do nothing in the chunk (see :func:`_moving`) are left out of the loop."""
    moving = None if leaks_all else _moving(levels, on, off, leak_hz, ideal, d, blind)
    if moving is not None:
        index = moving.nonzero().squeeze(1)
        part, d_moving, blind_moving = _crossings_all(levels[:, :, index], times, on[:, index], off[:, index],
                                                      refractory, leak_hz, leaks, ideal, d[:, index], blind[:, index])
        sample, pixel, t, p = part
        d = d.index_copy(1, index, d_moving)
        blind = blind.index_copy(1, index, blind_moving)
        return (sample, index[pixel], t, p), d, blind
    return _crossings_all(levels, times, on, off, refractory, leak_hz, leaks, ideal, d, blind)


def _moving(levels: Tensor, on: Tensor, off: Tensor, leak_hz: Tensor, ideal: bool, d: Tensor, blind: Tensor
            ) -> Tensor | None:
    """``(P,)`` the pixels the chunk must compute, or ``None`` to compute them all (few are still;
    the caller skips this where every sample leaks, when no pixel is still).

    A pixel is still in every sample when its level does not change in the chunk (the slope
    is exactly 0), its sample has no leak, it is not blind, and the step's own arithmetic on
    its state gives no event: then each step leaves its state as it was (up to the sign of a
    zero) and emits nothing, so leaving it out changes no output."""
    static = (levels[:, 1:] == levels[:, :1]).all(dim=1) & (leak_hz == 0) & (blind == 0)
    if ideal:  # the ideal step with change = d: trunc(d / theta) == 0
        quiet = torch.div(d, torch.where(d > 0, on, off)).trunc_() == 0
    else:  # the refractory step with slope 0: beyond = 0 - (off + d), n = floor(beyond / off) + 1 <= 0
        quiet = torch.div(0.0 - (off + d), off).floor_().add_(1.0) <= 0
    moving = ~(static & quiet).all(dim=0)
    count = int(read_host(moving.sum()))
    return moving if count < 0.9 * moving.numel() else None


def _crossings_all(levels: Tensor, times: Tensor, on: Tensor, off: Tensor, refractory: Tensor, leak_hz: Tensor,
                   leaks: bool, ideal: bool, d: Tensor, blind: Tensor
                   ) -> tuple[tuple[Tensor, Tensor, Tensor, Tensor], Tensor, Tensor]:
    """:func:`_crossings` on every pixel given."""
    device = levels.device
    batch, steps, pixels = levels.shape
    intervals = times.diff(dim=1).to(torch.float32)  # (B, C)
    leak = on * leak_hz * 1e-6  # reference decay, log units per µs
    count = steps - 1
    counts = torch.empty(count, batch, pixels, dtype=torch.int32, device=device)
    d_start = torch.empty(count, batch, pixels, dtype=torch.float32, device=device)
    rate = torch.empty_like(d_start)
    blind_spent = None if ideal else torch.empty_like(d_start)
    previous = levels[:, 0]
    for k in range(count):
        level = levels[:, k + 1]
        dt = intervals[:, k : k + 1]
        slope = torch.sub(level, previous, out=rate[k]).div_(dt)
        if leaks:
            slope.add_(leak)
        if ideal:  # no blind time: the rule trunc(change / threshold), in closed form
            d_start[k] = d
            change = torch.addcmul(d, slope, dt)
            theta = torch.where(change > 0, on, off)
            n = torch.div(change, theta).trunc_()
            counts[k] = n
            d = change.sub_(n.mul_(theta))
        else:
            assert blind_spent is not None
            d, blind = _refractory_step(d, blind, slope, dt, on, off, refractory, counts[k], d_start[k],
                                        blind_spent[k])
        previous = level
    return _chunk_events(counts, d_start, blind_spent, rate, times, 0, on, off, refractory), d, blind


def _refractory_step(d: Tensor, blind: Tensor, slope: Tensor, dt: Tensor, on: Tensor, off: Tensor, refractory: Tensor,
                     counts: Tensor, d_start: Tensor, blind_spent: Tensor) -> tuple[Tensor, Tensor]:
    """One frame interval with a refractory period: the counts and the state it starts with
    are written to ``counts``, ``d_start``, ``blind_spent``; returns the new ``(d, blind)``."""
    rising = slope > 0
    theta = torch.where(rising, on, off)
    sign = torch.where(rising, 1.0, -1.0)
    speed = slope.abs()
    torch.minimum(blind, dt, out=blind_spent)
    start = torch.where(blind > 0, 0.0, d)
    d_start.copy_(start)
    travel = speed * (dt - blind_spent)
    to_first = theta - sign * start  # how far the level must go to the first crossing
    blind_travel = speed * refractory
    spacing = theta + blind_travel
    beyond = travel - to_first
    n = torch.div(beyond, spacing).floor_().add_(1.0).clamp_min_(0.0)  # beyond < 0: no crossing
    counts.copy_(n * sign)
    fired = n > 0
    remaining = beyond - (n - 1.0) * spacing - blind_travel  # travel left after the last blind time
    after = remaining > 0
    d_new = torch.where(fired, torch.where(after, sign * remaining, 0.0), start + sign * travel)
    blind_new = torch.where(fired, torch.where(after, 0.0, -remaining / speed.clamp_min(1e-30)),
                            (blind - dt).clamp_min(0.0))
    return d_new, blind_new


def _empty(batch: int, sensor_size: tuple[int, int], device: torch.device) -> EventBatch:
    def column(dtype: torch.dtype) -> Tensor:
        return torch.zeros(0, dtype=dtype, device=device)

    return EventBatch(column(torch.int16), column(torch.int16), column(torch.int64), column(torch.int8),
                      torch.zeros(batch + 1, dtype=torch.int64), sensor_size)


def _assemble(parts: list[tuple[Tensor, Tensor, Tensor, Tensor]], batch: int, sensor_size: tuple[int, int],
              device: torch.device) -> EventBatch:
    """One EventBatch from (sample, pixel, t, p) parts: grouped by sample, sorted by time then pixel."""
    sample = torch.cat([part[0] for part in parts])
    pixel = torch.cat([part[1] for part in parts])
    t = torch.floor(torch.cat([part[2] for part in parts])).to(torch.int64)
    p = torch.cat([part[3] for part in parts])
    if sample.numel() == 0:
        return _empty(batch, sensor_size, device)
    pixels = sensor_size[0] * sensor_size[1]
    low, high = (int(v) for v in read_host(torch.stack([t.min(), t.max()])))
    span = (high - low + 1) * pixels
    lengths = torch.bincount(sample, minlength=batch).cpu()
    offsets = torch.cat([torch.zeros(1, dtype=torch.int64), lengths.cumsum(0)])
    width = sensor_size[1]
    if span * batch < 2**62:  # one stable sort by (sample, time, pixel): ties keep their order
        key = (t - low).mul_(pixels).add_(pixel)
        if batch > 1:
            key.add_(sample * span)
        values, order = torch.sort(key, stable=True)
        if batch > 1:
            values = values.remainder_(span)
        time = torch.div(values, pixels, rounding_mode="floor")
        pixel = (values - time * pixels).to(torch.int32)
        t = time.add_(low)
    else:
        order = torch.argsort(pixel, stable=True)
        order = order[torch.argsort(t[order], stable=True)]
        if batch > 1:
            order = order[torch.argsort(sample[order], stable=True)]
        pixel = pixel[order].to(torch.int32)
        t = t[order]
    y = torch.div(pixel, width, rounding_mode="floor")  # int32: pixel < 2**30, the faster division
    x = pixel - y * width
    return EventBatch(x.to(torch.int16), y.to(torch.int16), t, p[order], offsets, sensor_size)
