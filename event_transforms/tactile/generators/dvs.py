"""The built-in simulator's DVS pixel model (numpy): log intensity over time -> events.

The same model is the library's :func:`event_transforms.functional.emulate_events` (batched, on
the device, counter-based draws, crossing times interpolated inside each step), which the
optical generator uses since ``OPTICAL_VERSION`` 2. The built-in simulator still calls this
module, so its seeds give the events they always gave (its pinned results stand); moving it to
the library op changes every built-in result and is left for a regeneration of the main job.

Each pixel of a dynamic vision sensor remembers the log intensity at its last event (its
*reference*) and emits an ON (OFF) event whenever the log intensity has risen (fallen) by its
contrast threshold since then; the reference then moves by that threshold. This is the model
of the published DVS emulators, ESIM (Rebecq, Gehrig & Scaramuzza, CoRL 2018) and v2e (Hu,
Liu & Delbruck, CVPR Workshops 2021), with their non-ideal effects:

- **Per-pixel contrast thresholds with mismatch**: ON and OFF thresholds ``θ·(1 + σ·z)``, z
  standard normal per pixel, kept above 10 % of nominal. Here θ = 0.2 and σ = 0.03 by
  default (v2e's ``pos_thres``/``neg_thres`` and ``sigma_thres``; ESIM's contrast threshold C).
- **Refractory period**: a pixel is blind for ``refractory_us`` after it fires (its reference
  follows the light meanwhile, so changes during that time are lost); at most
  ``dt // refractory`` events per pixel and time step (v2e's ``refractory_period_s``;
  200 µs here).
- **Shot noise**: Poisson background events at a per-pixel rate drawn log-uniformly from
  0.1-10 Hz, ON with probability ½ (v2e's ``shot_noise_rate_hz``; the rates are the built-in
  simulator's setting, chosen for the paper's setup, not v2e's default).
- **Hot pixels**: a fraction (1e-4) of pixels firing at 50-200 Hz.
- **Leak events**: the reference decays by ``θ_ON · leak_hz`` per second, so a pixel under
  constant light emits an ON event every ``1 / leak_hz`` seconds, at a random phase per pixel
  and recording (v2e: ``leak_rate_hz`` 0.1 Hz with a random initial reference). The built-in
  simulator has no leak (rate 0, the behaviour its seeds were fixed with); the optical
  generator uses 0.1 Hz.
- **Lin-log response** (:func:`lin_log`, v2e's): log of the luminance above 20 DN (of 255),
  linear below, so dark pixels are not infinitely sensitive (the optical generator's; the
  built-in one darkens a uniform light and takes ``log1p`` directly).

The log intensity is rounded to 2⁻²⁰ (:func:`quantize_log`) before thresholding, so that
last-bit differences between math libraries cannot change an event. Events within one time
step are spread evenly over it (:func:`spread_events`). Camera properties (thresholds, noise
rates, hot pixels) come from one seed (:func:`camera`), so every recording of one camera
shares them; randomness of a recording comes from the generators the caller passes.
"""

from __future__ import annotations

__all__ = [
    "LOG_QUANTUM",
    "Camera",
    "camera",
    "quantize_log",
    "lin_log",
    "threshold_crossings",
    "spread_events",
    "noise_events",
    "background_events",
    "leak_events",
]

import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

#: Resolution of the log intensity before thresholding (machine independence).
LOG_QUANTUM = 2.0**-20


@dataclass(frozen=True)
class Camera:
    """A camera's fixed pixel properties, flattened row-major over ``(H, W)``.

    Attributes:
        threshold_on, threshold_off: per-pixel contrast thresholds (log units, positive).
        noise_hz: per-pixel shot-noise rate.
        hot_hz: extra rate of the hot pixels (0 elsewhere).
    """

    threshold_on: np.ndarray
    threshold_off: np.ndarray
    noise_hz: np.ndarray
    hot_hz: np.ndarray


def _log_uniform(rng: np.random.Generator, low: float, high: float, size: int) -> np.ndarray:
    return np.exp(rng.uniform(np.log(low), np.log(high), size))


@functools.lru_cache(maxsize=8)
def camera(
    sensor_size: tuple[int, int],
    seed: int,
    threshold: float,
    threshold_mismatch: float,
    shot_noise_hz: tuple[float, float],
    hot_pixel_fraction: float,
    hot_pixel_hz: tuple[float, float],
) -> Camera:
    """A camera's pixel properties, drawn from ``seed`` (read-only arrays, cached).

    Args:
        sensor_size: ``(H, W)``.
        seed: the camera's seed (every recording of one camera shares it).
        threshold: nominal contrast threshold θ (ON and OFF).
        threshold_mismatch: relative standard deviation σ of the per-pixel thresholds.
        shot_noise_hz: ``(low, high)`` range of the per-pixel noise rates (log-uniform).
        hot_pixel_fraction: fraction of hot pixels.
        hot_pixel_hz: ``(low, high)`` range of their rates (log-uniform).

    Example:
        >>> cam = camera((4, 5), 0, 0.2, 0.03, (0.1, 10.0), 0.1, (50.0, 200.0))
        >>> cam.threshold_on.shape, int((cam.hot_hz > 0).sum())
        ((20,), 2)
    """
    pixels = sensor_size[0] * sensor_size[1]
    rng_threshold, rng_noise, rng_hot = (
        np.random.Generator(np.random.PCG64(child)) for child in np.random.SeedSequence([seed, 0x5E45]).spawn(3)
    )
    if threshold_mismatch > 0:
        spread = threshold_mismatch * rng_threshold.standard_normal((2, pixels))
        # A threshold cannot vanish: keep at least 10 % of nominal (a 30-sigma event).
        thresholds = threshold * np.maximum(1.0 + spread, 0.1)
    else:
        thresholds = np.full((2, pixels), threshold)
    noise = _log_uniform(rng_noise, *shot_noise_hz, pixels)
    hot = np.zeros(pixels)
    n_hot = int(round(hot_pixel_fraction * pixels))
    if n_hot:
        where = rng_hot.choice(pixels, size=n_hot, replace=False)
        hot[where] = _log_uniform(rng_hot, *hot_pixel_hz, n_hot)
    for array in (thresholds, noise, hot):
        array.setflags(write=False)
    return Camera(thresholds[1], thresholds[0], noise, hot)


def quantize_log(level: np.ndarray) -> np.ndarray:
    """Round log intensities to :data:`LOG_QUANTUM` (the same events on any machine).

    Args:
        level: log intensities.

    Example:
        >>> float(quantize_log(np.array([0.1]))[0]) == round(0.1 * 2**20) / 2**20
        True
    """
    return np.round(level / LOG_QUANTUM) * LOG_QUANTUM


def lin_log(luminance: np.ndarray, *, knee_dn: float = 20.0) -> np.ndarray:
    """v2e's lin-log response to a luminance in [0, 1], in digital numbers ``x = 255 · luminance``:
    ``log(x)`` above ``knee_dn``, the linear ramp ``x · log(knee_dn) / knee_dn`` below
    (continuous and increasing), so a dark pixel is not infinitely sensitive.

    Args:
        luminance: luminance in [0, 1].
        knee_dn: the knee in digital numbers (v2e's 20).

    Example:
        >>> [round(float(v), 4) for v in lin_log(np.array([0.0, 10 / 255, 20 / 255, 1.0]))]
        [0.0, 1.4979, 2.9957, 5.5413]
    """
    x = 255.0 * np.asarray(luminance, dtype=np.float64)
    return np.where(x > knee_dn, np.log(np.maximum(x, knee_dn)), x * (np.log(knee_dn) / knee_dn))


def threshold_crossings(
    level_at: Callable[[int], np.ndarray],
    n_steps: int,
    threshold_on: np.ndarray,
    threshold_off: np.ndarray,
    dt_us: float,
    refractory_us: float,
    *,
    reference: np.ndarray | None = None,
    leak_per_step: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The DVS pixels' threshold crossings over ``n_steps`` time steps.

    Args:
        level_at: ``step -> (P,)`` log intensity of the P pixels at step ``step`` (0 ... n_steps - 1).
        n_steps: number of time steps (the first, step 0, sets the references).
        threshold_on, threshold_off: ``(P,)`` positive thresholds.
        dt_us: step length, microseconds.
        refractory_us: blind time after an event (0: none).
        reference: ``(P,)`` initial references (default: the level at step 0).
        leak_per_step: ``(P,)`` amount the references decay by per step (leak events).

    Returns:
        ``(step, pixel, signed count)`` of every (step, pixel) that fired: ``count`` events of
        the sign's polarity at that step (positive ON).

    Example:
        >>> ramp = lambda step: np.array([0.375 * step])  # +0.375 per step
        >>> steps, pixels, counts = threshold_crossings(ramp, 5, np.array([0.25]), np.array([0.25]), 1000.0, 0.0)
        >>> steps.tolist(), counts.tolist()  # a 1.5 rise: floor(1.5 / 0.25) = 6 events
        ([1, 2, 3, 4], [1, 2, 1, 2])
    """
    cap = max(1, int(dt_us // refractory_us)) if refractory_us > 0 else None
    reference = (level_at(0) if reference is None else np.array(reference, dtype=np.float64))
    last_fire = np.full(reference.size, -np.inf)
    fired_step, fired_index, fired_count = [], [], []
    for step in range(1, n_steps):
        level = level_at(step)
        now = step * dt_us
        if leak_per_step is not None:
            reference = reference - leak_per_step
        if refractory_us > 0:
            blind = (now - last_fire) < refractory_us
            reference = np.where(blind, level, reference)
        change = level - reference
        threshold = np.where(change > 0, threshold_on, threshold_off)
        count = np.trunc(change / threshold)
        fired = np.flatnonzero(count)
        if fired.size == 0:
            continue
        n = count[fired]
        if cap is not None:
            capped = np.clip(n, -cap, cap)
            reference[fired] = np.where(capped == n, reference[fired] + n * threshold[fired], level[fired])
            n = capped
            last_fire[fired] = now
        else:
            reference[fired] += n * threshold[fired]
        fired_step.append(np.full(fired.size, step))
        fired_index.append(fired)
        fired_count.append(n.astype(np.int64))
    if not fired_index:
        empty = np.zeros(0, np.int64)
        return empty, empty, empty
    return np.concatenate(fired_step), np.concatenate(fired_index), np.concatenate(fired_count)


def spread_events(
    steps: np.ndarray, signed: np.ndarray, dt_us: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One event per count: the n events of one step spread evenly over the step before it,
    ``t = (step - 1)·dt + dt·(k + ½)/n``.

    Args:
        steps: the step of each fired (step, pixel) row.
        signed: its signed count (positive ON).
        dt_us: step length, microseconds.

    Returns:
        ``(which, t_us, p)``: ``which`` indexes the input rows, ``p`` 1 for ON, 0 for OFF.

    Example:
        >>> which, t, p = spread_events(np.array([1, 2]), np.array([2, -1]), 1000.0)
        >>> which.tolist(), t.tolist(), p.tolist()
        ([0, 0, 1], [250, 750, 1500], [1, 1, 0])
    """
    count = np.abs(signed)
    repeat = np.repeat(np.arange(steps.size), count)
    k = np.arange(repeat.size) - np.repeat(np.cumsum(count) - count, count)
    t_us = np.floor((steps[repeat] - 1) * dt_us + dt_us * (k + 0.5) / count[repeat]).astype(np.int64)
    polarity = (signed[repeat] > 0).astype(np.int8)
    return repeat, t_us, polarity


def noise_events(
    rate_hz: np.ndarray, duration_us: int, on_fraction: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Homogeneous Poisson events per pixel: ``(pixel, t_us, p)`` (unsorted).

    Args:
        rate_hz: per-pixel rates.
        duration_us: recording length, microseconds.
        on_fraction: probability that an event is ON.
        rng: the recording's generator for this noise.

    Example:
        >>> pixel, t, p = noise_events(np.array([0.0, 1e4]), 1000, 0.5, np.random.default_rng(0))
        >>> bool((pixel == 1).all()), bool((t < 1000).all())
        (True, True)
    """
    counts = rng.poisson(rate_hz * duration_us * 1e-6)
    pixel = np.repeat(np.arange(rate_hz.size), counts)
    t = rng.integers(0, duration_us, pixel.size)
    p = (rng.random(pixel.size) < on_fraction).astype(np.int8)
    return pixel, t, p


def background_events(
    cam: Camera,
    duration_us: int,
    on_fraction: float,
    rng_shot: np.random.Generator | None,
    rng_hot: np.random.Generator | None,
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Shot noise (``rng_shot``; ``None``: off) and hot pixels (``rng_hot``; ``None``: off)
    of a camera: a list of ``(pixel, t_us, p)`` parts.

    Args:
        cam: the camera (:func:`camera`).
        duration_us: recording length, microseconds.
        on_fraction: probability that a noise event is ON.
        rng_shot: generator of the shot noise, ``None`` for none.
        rng_hot: generator of the hot pixels' events, ``None`` for none.

    Example:
        >>> cam = camera((4, 5), 0, 0.2, 0.03, (0.1, 10.0), 0.1, (50.0, 200.0))
        >>> parts = background_events(cam, 100_000, 0.5, None, np.random.default_rng(0))
        >>> len(parts), bool(np.isin(parts[0][0], np.flatnonzero(cam.hot_hz)).all())
        (1, True)
    """
    parts = []
    if rng_shot is not None:
        parts.append(noise_events(cam.noise_hz, duration_us, on_fraction, rng_shot))
    if rng_hot is not None and cam.hot_hz.any():
        hot = np.flatnonzero(cam.hot_hz)
        pixel, t, p = noise_events(cam.hot_hz[hot], duration_us, on_fraction, rng_hot)
        parts.append((hot[pixel], t, p))
    return parts


def leak_events(
    leak_hz: np.ndarray, phase: np.ndarray, duration_us: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Leak events of pixels under constant light: pixel ``i`` fires ON at
    ``(k + 1 - phase[i]) / leak_hz[i]`` seconds, k = 0, 1, ... (its reference starts
    ``phase · θ_ON`` below the level and decays by ``θ_ON · leak_hz`` per second).

    Args:
        leak_hz: per-pixel leak rates (0: none).
        phase: per-pixel phases in [0, 1) (the recording's random initial references).
        duration_us: recording length, microseconds.

    Returns:
        ``(pixel, t_us, p)`` (p all 1), sorted by pixel.

    Example:
        >>> pixel, t, p = leak_events(np.array([10.0, 0.0]), np.array([0.5, 0.5]), 200_000)
        >>> pixel.tolist(), t.tolist()
        ([0, 0], [50000, 150000])
    """
    rate = np.asarray(leak_hz, dtype=np.float64)
    safe = np.where(rate > 0, rate, 1.0)
    first_s = (1.0 - np.asarray(phase, dtype=np.float64)) / safe
    duration_s = duration_us * 1e-6
    fires = (rate > 0) & (first_s < duration_s)
    count = np.where(fires, np.floor((duration_s - np.minimum(first_s, duration_s)) * rate) + 1, 0).astype(np.int64)
    pixel = np.repeat(np.arange(rate.size), count)
    k = np.arange(pixel.size) - np.repeat(np.cumsum(count) - count, count)
    t_us = np.floor((first_s[pixel] + k / safe[pixel]) * 1e6).astype(np.int64)
    keep = t_us < duration_us
    return pixel[keep], t_us[keep], np.ones(int(keep.sum()), np.int8)
