"""A seeded simulator of the paper's tactile setup: a bolt grasped against a silicone membrane.

The paper's recordings are not public, so the package ships a small physical model of
them. One *grasp* is:

1. **Force.** A parallel gripper closes on a bolt of diameter D: a smooth ramp over the
   first ~5 frames, a hold with vibration, a release over the last ~5 frames. Each gripper
   setting has a nominal hold force; experiments vary around it (capped at 25 N). The
   force/torque sensor reads the true force every 10 ms, at the frame centres.
2. **Membrane.** The membrane follows the force through a first-order lag with a time
   constant drawn per experiment, τ dF_m/dt = F − F_m (the creep of a Zener solid).
3. **Contact.** The bolt leaves a dark strip on the membrane whose half-width follows
   Hertz line contact, b = k·(F_m·R)^e with R = D/2 and e = 1/2 (thin layers are nearer
   1/3; the exponent is configurable). The strip has a fixed length (the gripper pad), an
   orientation drawn per experiment, and a centre near the sensor centre.

   **Size models.** How the strip changes with the bolt diameter D is a modelling choice,
   and the benchmark's size verdicts depend on it (``benchmarks/tactile/physics_sensitivity.py``).
   By default only the half-width grows with D (as √D), so a stretch across the strip by
   √(D₂/D₁) is the generator's exact inverse. :data:`SIZE_MODELS` names documented
   variants: ``"hertz"`` (the default), ``"thin-layer"`` (e = ⅓: a thin membrane on a
   rigid backing), ``"hertz-growing"`` and ``"thin-layer-growing"`` (additionally the
   strip's half-length grows as (D/D_ref)^½, a thicker bolt's curved ends reaching further
   along the pad, and its contrast as (D/D_ref)^½, a deeper indentation darkening more),
   via ``strip_length_exponent`` and ``contrast_exponent``.
4. **DVS.** The camera sees the membrane's log intensity on a fine time grid (1 ms
   substeps) on the pixels a strip can touch, through the library's pixel model
   (:func:`~event_transforms.functional.threshold_crossings`, the core of
   :func:`~event_transforms.functional.emulate_events`, which the optical generator uses):
   each pixel emits an ON (OFF) event whenever its log intensity rose (fell) by its
   threshold since its last event (v2e/ESIM), with per-pixel threshold mismatch and a
   refractory period during which its reference follows the light; the log intensity is
   interpolated linearly between substeps, so each event has its crossing time. Background
   shot noise (0.1–10 Hz per pixel, log-uniform) and hot pixels (each pixel hot with
   probability ``hot_pixel_fraction``, 50–200 Hz) are Poisson events
   (:func:`~event_transforms.functional.noise_events`).

Every effect has a switch in :class:`SimulatorConfig`, and an effect that is off is not
computed. The experiment's draws (:func:`draw_grasp`) come from a
``numpy.random.Generator(PCG64)`` stream derived from the seed with ``SeedSequence``; the
camera's draws are the library's counter-based ones (:mod:`event_transforms.functional`):
fixed pixel properties (threshold mismatch, noise rates, hot pixels) come from
``camera_seed = sensor_seed`` (:func:`~event_transforms.functional.camera_pixels`), so every
recording of one data set shares them, as recordings from one camera do, and the noise
events from ``seed`` = the grasp's seed, so a grasp simulated alone equals the same grasp in
a batch. Shot noise and hot pixels are one Poisson process over the pixels' summed rates:
switching hot pixels off changes the shot noise's realisation (never the contact events).
Nothing touches a global RNG. The log intensity is rounded to 2⁻²⁰ before thresholding so
that last-bit differences between math libraries cannot change an event: same seed, same
events on any machine. ``SIMULATOR_VERSION`` 3 (this model) replaced version 2's numpy
model (thresholds per step, events spread evenly inside a step, at most ``dt // refractory``
events a step, numpy noise streams): a seed gives other events than before.

Results obtained on this data are results on synthetic data, never the paper's.
"""

from __future__ import annotations

__all__ = [
    "SIMULATOR_VERSION",
    "SIZE_MODELS",
    "SimulatorConfig",
    "Grasp",
    "Recording",
    "EVENT_DTYPE",
    "draw_grasp",
    "force_profile",
    "membrane_force",
    "contact_half_width",
    "simulate_grasps",
    "simulate_grasp",
    "simulate_static",
]

import dataclasses
import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
from torch import Tensor

from ..events.binning import events_to_frames
from ..functional import LOG_QUANTUM, camera_pixels, noise_events, threshold_crossings

#: Bumped whenever the model changes what a seed produces (keys the data-set cache).
SIMULATOR_VERSION = 3
_Parts = list[tuple[np.ndarray, np.ndarray, np.ndarray]]  # (pixel, t_us, p) parts of a recording
#: Levels per call of the pixel model (pixels times substeps): bounds the memory of a batch of grasps.
_CHUNK_LEVELS = 1 << 20

#: Structured dtype of simulated event streams (tonic's field names; t in microseconds).
EVENT_DTYPE = np.dtype([("x", np.int16), ("y", np.int16), ("t", np.int64), ("p", np.int8)])



@dataclass(frozen=True)
class SimulatorConfig:
    """Settings of the simulated setup. Every effect can be switched off.

    Switches: ``contact`` (no contact: a static scene), ``force_variation = 0`` (every
    experiment of a gripper setting gets its nominal force), ``timing_jitter_ms = 0``,
    ``vibration``, ``lag`` (membrane follows the force instantly), ``orientation`` (strip
    always horizontal), ``center_jitter_px = 0`` (strip at the sensor centre),
    ``threshold_mismatch = 0``, ``refractory_us = 0``, ``shot_noise``, ``hot_pixels``.

    Attributes:
        sensor_size: (H, W) of the DVS; the paper's DAVIS240 is (180, 240).
        n_frames: frames per grasp (36 × 10 ms = 360 ms).
        frame_ms: frame length and force sampling period in milliseconds.
        substep_ms: time step of the log-intensity rendering.
        sensor_seed: seed of the camera's fixed pixel properties.
        gripper_force_n: nominal hold force of each gripper setting, newtons.
        force_variation: relative standard deviation of the hold force between experiments.
        hold_force_n: ``(min, max)``: draw every experiment's hold force uniformly from this
            range instead of around a gripper setting (continuous forces; ``gripper`` is
            then only a label). ``None``: gripper settings.
        max_force_n: the gripper's limit; hold forces (plus drift and vibration) are capped
            there.
        grasp_ms, release_ms: nominal ramp durations.
        ramp_variation: the ramps last ``(1 ± ramp_variation)`` times nominal (uniform).
        timing_jitter_ms: the grasp starts and the release ends up to this late/early.
        hold_drift: the force drifts linearly over the grasp by up to ± this fraction
            (uniform per experiment): the grip relaxes or tightens during the hold.
        delay_ms: ``(min, max)`` range of a transport delay between the force reading and
            the membrane (per experiment): the membrane sees the force of ``delay_ms``
            earlier, as with a clock offset between the F/T sensor and the camera or a
            viscous membrane. The recorded force (the label) is not delayed.
        vibration: add a sinusoidal vibration to the hold force.
        vibration_fraction: vibration amplitude relative to the force.
        vibration_hz: range of the vibration frequency (drawn per experiment).
        contact: render the contact strip (False gives a static scene).
        width_exponent: e in b = k·(F·R)^e (1/2: Hertz line contact).
        reference_half_width_px: b in pixels at the reference force and diameter.
        reference_force_n, reference_diameter_mm: the reference point fixing k.
        strip_half_length_px: half the strip's length along the bolt's axis.
        edge_px: width of the strip's soft edge.
        contrast: fractional darkening inside the strip (0 < contrast < 1) at the
            reference diameter.
        strip_length_exponent: the strip's half-length is ``strip_half_length_px ·
            (D / reference_diameter_mm) ** strip_length_exponent`` (0: fixed by the pad).
        contrast_exponent: the strip's contrast is ``contrast · (D /
            reference_diameter_mm) ** contrast_exponent``, capped at 0.95 (0: fixed).
        center_jitter_px: the strip centre is uniform within ± this of the sensor centre.
        lag: apply the membrane's first-order lag.
        lag_ms: range of the lag time constant τ (drawn per experiment).
        release_lag_ratio: the membrane's time constant while it relaxes (force below the
            membrane's) is this many times τ: a viscoelastic membrane recovers more slowly
            than it is pressed (1: symmetric, the old behaviour).
        label_lowpass_ms: the force/torque sensor's reading (the label) is the force through
            a first-order low-pass with this time constant (0: the true force, the old
            behaviour), as the paper's F/T sensor answers the release later than the events.
        orientation: rotate the strip by an angle drawn per experiment.
        angle_deg: range of that angle, degrees (counter-clockwise in the image).
        angle_symmetric: the angle's sign is drawn too (so ``angle_deg=(25, 45)`` gives
            angles in [-45, -25] ∪ [25, 45]).
        threshold: nominal log-intensity contrast threshold (ON and OFF).
        threshold_mismatch: relative standard deviation of per-pixel thresholds.
        refractory_us: a pixel is blind this long after it fires (its reference follows
            the light meanwhile, so changes during that time are lost). 0 here: version 2's
            200 µs never acted at 1 ms substeps (CHANGELOG); the optical scenes' is 200.
        shot_noise: add background shot noise.
        shot_noise_hz: range of the per-pixel noise rates (log-uniform per pixel).
        noise_on_fraction: probability that a noise event is ON.
        hot_pixels: add hot pixels.
        hot_pixel_fraction: probability that a pixel is hot (drawn per pixel of the camera).
        hot_pixel_hz: range of the hot pixels' rates (log-uniform).
    """

    sensor_size: tuple[int, int] = (180, 240)
    n_frames: int = 36
    frame_ms: float = 10.0
    substep_ms: float = 1.0
    sensor_seed: int = 0
    gripper_force_n: tuple[float, ...] = (12.0, 20.0)
    force_variation: float = 0.1
    hold_force_n: tuple[float, float] | None = None
    max_force_n: float = 25.0
    grasp_ms: float = 50.0
    release_ms: float = 50.0
    ramp_variation: float = 0.2
    timing_jitter_ms: float = 5.0
    hold_drift: float = 0.0
    delay_ms: tuple[float, float] = (0.0, 0.0)
    vibration: bool = True
    vibration_fraction: float = 0.03
    vibration_hz: tuple[float, float] = (15.0, 40.0)
    contact: bool = True
    width_exponent: float = 0.5
    reference_half_width_px: float = 12.0
    reference_force_n: float = 25.0
    reference_diameter_mm: float = 18.0
    strip_half_length_px: float = 45.0
    edge_px: float = 1.5
    contrast: float = 0.6
    center_jitter_px: float = 6.0
    lag: bool = True
    lag_ms: tuple[float, float] = (2.0, 25.0)
    orientation: bool = True
    angle_deg: tuple[float, float] = (-20.0, 20.0)
    angle_symmetric: bool = False
    threshold: float = 0.2
    threshold_mismatch: float = 0.03
    refractory_us: float = 0.0
    shot_noise: bool = True
    shot_noise_hz: tuple[float, float] = (0.1, 10.0)
    noise_on_fraction: float = 0.5
    hot_pixels: bool = True
    hot_pixel_fraction: float = 1e-4
    hot_pixel_hz: tuple[float, float] = (50.0, 200.0)
    # issue 18 (lag effects); their defaults leave every earlier seed's output unchanged
    release_lag_ratio: float = 1.0
    label_lowpass_ms: float = 0.0
    # issue 24 (size models); their defaults leave every earlier seed's output unchanged
    strip_length_exponent: float = 0.0
    contrast_exponent: float = 0.0

    def __post_init__(self) -> None:
        height, width = self.sensor_size
        if height < 1 or width < 1:
            raise ValueError(f"sensor_size must be positive, got {self.sensor_size!r}")
        steps = self.frame_ms / self.substep_ms
        if self.substep_ms <= 0 or abs(steps - round(steps)) > 1e-9:
            raise ValueError(
                f"frame_ms ({self.frame_ms}) must be a whole multiple of substep_ms "
                f"({self.substep_ms})"
            )
        if not 0 < self.contrast < 1:
            raise ValueError(f"contrast must lie in (0, 1), got {self.contrast!r}")
        if self.threshold <= 0:
            raise ValueError(f"threshold must be positive, got {self.threshold!r}")
        if min(self.gripper_force_n, default=0) <= 0:
            raise ValueError(f"gripper_force_n must be positive, got {self.gripper_force_n!r}")
        ranges = ["vibration_hz", "lag_ms", "angle_deg", "shot_noise_hz", "hot_pixel_hz", "delay_ms"]
        if self.hold_force_n is not None:
            ranges.append("hold_force_n")
            if not 0 <= self.hold_force_n[0] <= self.hold_force_n[1] <= self.max_force_n:
                raise ValueError(
                    f"hold_force_n must be a (min, max) range in [0, max_force_n={self.max_force_n}], "
                    f"got {self.hold_force_n!r}"
                )
        if not 0 <= self.ramp_variation < 1:
            raise ValueError(f"ramp_variation must lie in [0, 1), got {self.ramp_variation!r}")
        if not 0 <= self.hold_drift < 1:
            raise ValueError(f"hold_drift must lie in [0, 1), got {self.hold_drift!r}")
        if self.delay_ms[0] < 0:
            raise ValueError(f"delay_ms must be non-negative, got {self.delay_ms!r}")
        for name in ranges:
            low, high = getattr(self, name)
            if low > high:
                raise ValueError(f"{name} must be a (min, max) pair, got {(low, high)!r}")
        if not (self.release_lag_ratio > 0 and math.isfinite(self.release_lag_ratio)):
            raise ValueError(f"release_lag_ratio must be a positive number, got {self.release_lag_ratio!r}")
        for name in ("strip_length_exponent", "contrast_exponent", "width_exponent"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be a finite number, got {getattr(self, name)!r}")
        if not (self.label_lowpass_ms >= 0 and math.isfinite(self.label_lowpass_ms)):
            raise ValueError(f"label_lowpass_ms must be non-negative, got {self.label_lowpass_ms!r}")
        if self.lag and self.lag_ms[0] <= 0:
            raise ValueError(f"lag_ms must be positive (or set lag=False), got {self.lag_ms!r}")
        for name in ("shot_noise_hz", "hot_pixel_hz"):
            if getattr(self, name)[0] <= 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)!r}")

    @property
    def duration_ms(self) -> float:
        """Length of one recording, ``n_frames · frame_ms``."""
        return self.n_frames * self.frame_ms

    def replace(self, **changes: Any) -> SimulatorConfig:
        """A copy with some settings changed (``dataclasses.replace``)."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class Grasp:
    """The parameters of one experiment, drawn by :func:`draw_grasp`."""

    diameter_mm: float
    gripper: int
    seed: int
    hold_force_n: float
    grasp_start_ms: float
    grasp_ms: float
    release_ms: float
    release_end_ms: float
    vibration_hz: float
    vibration_phase: float
    lag_ms: float
    angle_deg: float
    center_yx: tuple[float, float]
    hold_drift: float = 0.0
    delay_ms: float = 0.0


@dataclass(frozen=True, eq=False)
class Recording:
    """One simulated recording: an event stream and the force sampled every frame.

    Attributes:
        events: structured array with fields ``x, y, t, p`` (:data:`EVENT_DTYPE`), sorted
            by ``t`` (microseconds from ``t_start_us``); ``p`` is 1 for ON, 0 for OFF.
        force: (n_frames,) float32 force in newtons at the frame centres.
        force_t_us: (n_frames,) int64 times of the force samples.
        grasp: the experiment's parameters (``None`` for a static scene).
        config: the simulator settings that made it.
        t_start_us: start of the first frame.
    """

    events: np.ndarray
    force: np.ndarray
    force_t_us: np.ndarray
    grasp: Grasp | None
    config: SimulatorConfig = field(repr=False)
    t_start_us: int = 0

    def frames(
        self,
        *,
        crop: tuple[int, int, int, int] | None = None,
        pool: int = 1,
        dtype: torch.dtype = torch.float32,
    ) -> Tensor:
        """The recording as frames ``(n_frames, 2, H, W)`` (see :func:`events_to_frames`)."""
        return events_to_frames(
            self.events,
            t_start=self.t_start_us,
            frame_ms=self.config.frame_ms,
            n_frames=self.config.n_frames,
            sensor_size=self.config.sensor_size,
            crop=crop,
            pool=pool,
            dtype=dtype,
        )

    def sensor_crop(self, size: tuple[int, int] = (140, 150)) -> tuple[int, int, int, int]:
        """``(top, left, height, width)`` window of ``size`` centred on the *sensor*: a fixed
        crop that needs no knowledge of the contact (the benchmark's data use it; with the
        default ±6 px centre jitter and 45 px strip half-length the strip stays inside)."""
        height, width = self.config.sensor_size
        crop_h, crop_w = size
        if not (0 < crop_h <= height and 0 < crop_w <= width):
            raise ValueError(f"size must fit the sensor {self.config.sensor_size}, got {size!r}")
        return (height - crop_h) // 2, (width - crop_w) // 2, crop_h, crop_w

    def contact_crop(self, size: tuple[int, int] = (140, 150)) -> tuple[int, int, int, int]:
        """``(top, left, height, width)`` window of ``size`` centred on the contact, inside
        the sensor (the paper's 140×150 crop "around the contact area"). It reads the true
        contact centre, an oracle a real pipeline does not have: the benchmark's data use
        :meth:`sensor_crop` instead."""
        height, width = self.config.sensor_size
        crop_h, crop_w = size
        if not (0 < crop_h <= height and 0 < crop_w <= width):
            raise ValueError(f"size must fit the sensor {self.config.sensor_size}, got {size!r}")
        cy, cx = self.grasp.center_yx if self.grasp is not None else _sensor_center(self.config)
        top = min(max(int(round(cy - (crop_h - 1) / 2)), 0), height - crop_h)
        left = min(max(int(round(cx - (crop_w - 1) / 2)), 0), width - crop_w)
        return top, left, crop_h, crop_w


# --------------------------------------------------------------------------- experiment


def _check_seed(seed: object) -> None:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**63:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")


def _streams(seed: int) -> list[np.random.Generator]:
    """PCG64 streams of the experiment's draws (the first; the other two drew the noise before
    ``SIMULATOR_VERSION`` 3 and are kept so that the first stays the same)."""
    _check_seed(seed)
    children = np.random.SeedSequence(int(seed)).spawn(3)
    return [np.random.Generator(np.random.PCG64(child)) for child in children]


def _sensor_center(config: SimulatorConfig) -> tuple[float, float]:
    height, width = config.sensor_size
    return (height - 1) / 2, (width - 1) / 2


def draw_grasp(
    diameter_mm: float, *, gripper: int = 0, seed: int = 0, config: SimulatorConfig | None = None
) -> Grasp:
    """Draw one experiment's parameters.

    The draws depend on ``seed`` and ``config`` only, not on the diameter or the gripper
    setting, so two bolts simulated with one seed see the same force profile shape, lag,
    angle and centre. Effects switched off get their neutral value (no lag, angle 0, ...).

    Args:
        diameter_mm: bolt diameter in millimetres.
        gripper: index into ``config.gripper_force_n``.
        seed: experiment seed.
        config: simulator settings (defaults to :class:`SimulatorConfig()`).

    Example:
        >>> grasp = draw_grasp(15.0, gripper=1, seed=3)
        >>> grasp.diameter_mm, grasp.gripper, round(grasp.hold_force_n, 2)
        (15.0, 1, 21.05)
    """
    config = config or SimulatorConfig()
    if isinstance(diameter_mm, bool) or not isinstance(diameter_mm, (int, float)) or not (
        diameter_mm > 0 and math.isfinite(diameter_mm)
    ):
        raise ValueError(f"diameter_mm must be a positive number, got {diameter_mm!r}")
    if isinstance(gripper, bool) or not isinstance(gripper, (int, np.integer)) or not (
        0 <= gripper < len(config.gripper_force_n)
    ):
        raise ValueError(
            f"gripper must index gripper_force_n {config.gripper_force_n}, got {gripper!r}"
        )
    rng = _streams(seed)[0]
    # Always draw every number in the same order so switches do not shift the others
    # (numbers added in later versions are drawn after the older ones).
    force_z = float(rng.standard_normal())
    start_u, grasp_u, release_u, end_u, vib_u, phase_u, lag_u, angle_u = rng.random(8)
    center_u = rng.random(2)
    force_u, drift_u, delay_u, sign_u = rng.random(4)

    drift = config.hold_drift * (2 * drift_u - 1)
    if config.hold_force_n is None:
        hold = config.gripper_force_n[gripper] * (1.0 + config.force_variation * force_z)
    else:
        low_force, high_force = config.hold_force_n
        hold = low_force + (high_force - low_force) * force_u
    # The gripper's limit applies to the peak, drift and vibration included.
    peak = config.max_force_n / (
        (1.0 + (config.vibration_fraction if config.vibration else 0.0)) * (1.0 + abs(drift))
    )
    hold = float(min(max(hold, 0.0), peak))
    jitter = config.timing_jitter_ms
    ramp = config.ramp_variation
    low, high = config.vibration_hz
    cy, cx = _sensor_center(config)
    shift = config.center_jitter_px * (2 * center_u - 1)
    angle = config.angle_deg[0] + (config.angle_deg[1] - config.angle_deg[0]) * angle_u
    if config.angle_symmetric and sign_u < 0.5:
        angle = -angle
    return Grasp(
        diameter_mm=float(diameter_mm),
        gripper=int(gripper),
        seed=int(seed),
        hold_force_n=hold,
        grasp_start_ms=float(jitter * start_u),
        grasp_ms=float(config.grasp_ms * (1 - ramp + 2 * ramp * grasp_u)),
        release_ms=float(config.release_ms * (1 - ramp + 2 * ramp * release_u)),
        release_end_ms=float(config.duration_ms - jitter * end_u),
        vibration_hz=float(low + (high - low) * vib_u) if config.vibration else 0.0,
        vibration_phase=float(2 * np.pi * phase_u),
        lag_ms=float(config.lag_ms[0] + (config.lag_ms[1] - config.lag_ms[0]) * lag_u)
        if config.lag
        else 0.0,
        angle_deg=float(angle) if config.orientation else 0.0,
        center_yx=(float(cy + shift[0]), float(cx + shift[1])),
        hold_drift=float(drift),
        delay_ms=float(config.delay_ms[0] + (config.delay_ms[1] - config.delay_ms[0]) * delay_u),
    )


def _smoothstep(u: np.ndarray) -> np.ndarray:
    return 0.5 - 0.5 * np.cos(np.pi * np.clip(u, 0.0, 1.0))


def force_profile(grasps: Sequence[Grasp], times_ms: np.ndarray, config: SimulatorConfig) -> np.ndarray:
    """The gripper force (newtons) of each grasp at ``times_ms``, shape (len(grasps), len(times)).

    A raised-cosine ramp up over ``grasp_ms``, a hold that drifts linearly by
    ``hold_drift`` (relative, from the start of the grasp to the end of the release) with a
    sinusoidal vibration (if switched on), and a raised-cosine ramp down ending at
    ``release_end_ms``. ``times_ms`` is ``(S,)`` (shared) or ``(len(grasps), S)``.
    """
    times = np.asarray(times_ms, dtype=np.float64)
    if times.ndim == 1:
        times = times[None, :]
    column = lambda name: np.array([getattr(g, name) for g in grasps], dtype=np.float64)[:, None]  # noqa: E731
    start, ramp_up = column("grasp_start_ms"), column("grasp_ms")
    end, ramp_down = column("release_end_ms"), column("release_ms")
    envelope = _smoothstep((times - start) / ramp_up) * (1.0 - _smoothstep((times - end + ramp_down) / ramp_down))
    progress = np.clip((times - start) / np.maximum(end - start, 1e-9), 0.0, 1.0)
    force = column("hold_force_n") * envelope * (1.0 + column("hold_drift") * (2 * progress - 1))
    if config.vibration:
        wave = np.sin(2 * np.pi * column("vibration_hz") * times / 1000.0 + column("vibration_phase"))
        force = force * (1.0 + config.vibration_fraction * wave)
    return force


def membrane_force(
    force: np.ndarray, lag_ms: np.ndarray, substep_ms: float, *, release_ratio: float = 1.0
) -> np.ndarray:
    """First-order lag τ dF_m/dt = F − F_m on a uniform grid, per row (τ = 0: no lag).

    Exact for a force linear between grid points, so a ramp is delayed by exactly τ.
    ``force`` is (n, S) starting at rest (F_m = F at the first point), ``lag_ms`` (n,).
    With ``release_ratio`` ≠ 1, a step on which the force lies below the membrane's (the
    membrane relaxing) uses the time constant ``release_ratio · τ``.
    """
    lag_ms = np.asarray(lag_ms, dtype=np.float64)
    out = np.array(force, dtype=np.float64, copy=True)
    lagged = lag_ms > 0
    if not lagged.any():
        return out

    def constants(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        decay = np.zeros_like(tau)
        decay[lagged] = np.exp(-substep_ms / tau[lagged])
        # u(t) linear on a step with slope s: F_m(h) = u1 − τs + e^(−h/τ)·(F_m(0) − u0 + τs).
        return decay, tau[:, None] * np.diff(force, axis=1) / substep_ms

    decay, tau_slope = constants(lag_ms)
    if release_ratio != 1.0:
        release_decay, release_slope = constants(lag_ms * release_ratio)
    for step in range(1, force.shape[1]):
        if release_ratio == 1.0:
            d, drift = decay, tau_slope[:, step - 1]
        else:
            relaxing = force[:, step] < out[:, step - 1]
            d = np.where(relaxing, release_decay, decay)
            drift = np.where(relaxing, release_slope[:, step - 1], tau_slope[:, step - 1])
        out[:, step] = force[:, step] - drift + d * (out[:, step - 1] - force[:, step - 1] + drift)
    return out


def contact_half_width(
    force_n: np.ndarray | float, diameter_mm: np.ndarray | float, config: SimulatorConfig | None = None
) -> np.ndarray:
    """Half-width of the contact strip in pixels, b = k·(F·R)^e (Hertz line contact for e=½).

    ``k`` is fixed by ``reference_half_width_px`` at the reference force and diameter.

    Example:
        >>> config = SimulatorConfig()
        >>> float(contact_half_width(25.0, 18.0, config))
        12.0
        >>> round(float(contact_half_width(10.0, 18.0) / contact_half_width(10.0, 12.0)), 4)
        1.2247
    """
    config = config or SimulatorConfig()
    e = config.width_exponent
    reference = (config.reference_force_n * config.reference_diameter_mm / 2) ** e
    product = np.maximum(np.asarray(force_n, dtype=np.float64), 0.0) * np.asarray(diameter_mm) / 2
    return config.reference_half_width_px * product**e / reference


# --------------------------------------------------------------------------- camera


@functools.lru_cache(maxsize=8)
def _sensor(config: SimulatorConfig) -> tuple[Tensor, Tensor, Tensor]:
    """The camera's fixed pixel properties, ``(1, H·W)`` each: ON and OFF thresholds and noise rates
    (shot noise plus hot pixels), :func:`~event_transforms.functional.camera_pixels` of
    ``camera_seed = config.sensor_seed``. The ranges ``(low, high)`` are the library's geometric
    mean ``√(low·high)`` and spread ``√(high/low)``; an effect switched off has rate 0."""
    (shot_low, shot_high), (hot_low, hot_high) = config.shot_noise_hz, config.hot_pixel_hz
    return camera_pixels(
        config.sensor_size[0] * config.sensor_size[1], camera_seed=config.sensor_seed,
        threshold_on=config.threshold, mismatch=config.threshold_mismatch,
        noise_hz=math.sqrt(shot_low * shot_high) if config.shot_noise else 0.0,
        noise_spread=math.sqrt(shot_high / shot_low),
        hot_pixel_fraction=config.hot_pixel_fraction if config.hot_pixels else 0.0,
        hot_pixel_hz=math.sqrt(hot_low * hot_high), hot_pixel_spread=math.sqrt(hot_high / hot_low),
    )


def _background(seeds: Sequence[int], duration_us: int, config: SimulatorConfig) -> list[_Parts]:
    """Shot noise and hot pixels of recordings ``seeds`` (:func:`~event_transforms.functional.noise_events`
    with ``seed`` the recording's): per recording a list of ``(pixel, t_us, p)`` parts."""
    for seed in seeds:
        _check_seed(seed)
    if not seeds or not (config.shot_noise or config.hot_pixels):
        return [[] for _ in seeds]
    rates = _sensor(config)[2]
    sample, pixel, t, p = noise_events(rates.expand(len(seeds), -1), float(duration_us), seed=torch.tensor([int(v) for v in seeds]),
                                       on_fraction=config.noise_on_fraction)
    return _by_owner(sample.numpy(), pixel.numpy(), torch.floor(t).to(torch.int64).numpy(), p.numpy(), len(seeds))


def _by_owner(owner: np.ndarray, pixel: np.ndarray, t_us: np.ndarray, p: np.ndarray, count: int) -> list[_Parts]:
    """Split ``(pixel, t_us, p)`` rows by their owner ``0 .. count - 1``: one part list each."""
    order = np.argsort(owner, kind="stable")
    bounds = np.searchsorted(owner[order], np.arange(count + 1))
    return [[(pixel[order[lo:hi]], t_us[order[lo:hi]], p[order[lo:hi]])] for lo, hi in zip(bounds[:-1], bounds[1:])]


def _to_events(parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]], sensor_size: tuple[int, int]) -> np.ndarray:
    """Merge (pixel, t, p) parts into one structured array sorted by time, ties by pixel, then
    polarity (OFF first): rows equal in all three are identical, so the order is unique."""
    pixel = np.concatenate([part[0] for part in parts]) if parts else np.zeros(0, np.int64)
    t = np.concatenate([part[1] for part in parts]) if parts else np.zeros(0, np.int64)
    p = np.concatenate([part[2] for part in parts]) if parts else np.zeros(0, np.int8)
    height, width = sensor_size
    order = np.argsort((t * (height * width) + pixel) * 2 + p)  # a unique key up to identical rows
    events = np.empty(order.size, dtype=EVENT_DTYPE)
    events["x"] = pixel[order] % width
    events["y"] = pixel[order] // width
    events["t"] = t[order]
    events["p"] = p[order]
    return events


# --------------------------------------------------------------------------- simulation


#: Documented variants of how the contact strip changes with the bolt diameter: name ->
#: the :class:`SimulatorConfig` settings (see the module docstring, "Size models").
SIZE_MODELS: dict[str, dict[str, float]] = {
    "hertz": {"width_exponent": 0.5},
    "thin-layer": {"width_exponent": 1.0 / 3.0},
    "hertz-growing": {"width_exponent": 0.5, "strip_length_exponent": 0.5, "contrast_exponent": 0.5},
    "thin-layer-growing": {"width_exponent": 1.0 / 3.0, "strip_length_exponent": 0.5, "contrast_exponent": 0.5},
}


def _strip_shape(grasps: Sequence[Grasp], config: SimulatorConfig) -> tuple[np.ndarray, np.ndarray]:
    """Per grasp: the strip's half-length (px) and contrast under the size model."""
    ratio = np.array([g.diameter_mm for g in grasps], dtype=np.float64) / config.reference_diameter_mm
    half_length = config.strip_half_length_px * ratio**config.strip_length_exponent
    contrast = np.minimum(config.contrast * ratio**config.contrast_exponent, 0.95)
    return half_length, contrast


def _contact_events(
    grasps: Sequence[Grasp], width_px: np.ndarray, config: SimulatorConfig
) -> list[_Parts]:
    """DVS events of the strips, vectorised over the active pixels of every grasp.

    ``width_px`` is the half-width b of each grasp on the substep grid, (n, S + 1).
    The library's pixel model (:func:`~event_transforms.functional.threshold_crossings`) on
    the active pixels, the camera's thresholds and refractory period: the log intensity is
    interpolated linearly between substeps, so each event has its crossing time (in
    ``(k, k + 1]`` substeps for a crossing between substeps k and k + 1; one at the recording's
    very end, ``t = duration``, lies after it and is not kept). Returns per grasp a list of
    (pixel, t_us, p) parts.
    """
    height, width = config.sensor_size
    on, off, _ = _sensor(config)
    ys, xs = np.divmod(np.arange(height * width), width)
    edge = config.edge_px
    # Gather the pixels each strip can ever touch; every other pixel sees constant light.
    owners: list[np.ndarray] = []
    pixels: list[np.ndarray] = []
    acrosses: list[np.ndarray] = []
    alongs: list[np.ndarray] = []
    half_length, contrast = _strip_shape(grasps, config)
    for index, grasp in enumerate(grasps):
        theta = np.deg2rad(grasp.angle_deg)
        dy, dx = ys - grasp.center_yx[0], xs - grasp.center_yx[1]
        # Image rows grow downwards: a counter-clockwise angle has direction (cos, -sin).
        u = np.abs(dx * np.sin(theta) + dy * np.cos(theta))  # distance across the strip
        v = np.abs(dx * np.cos(theta) - dy * np.sin(theta))  # distance along it
        active = np.flatnonzero((u < width_px[index].max()) & (v < half_length[index]))
        owners.append(np.full(active.size, index))
        pixels.append(active)
        acrosses.append(u[active])
        alongs.append(v[active])
    owner, pixel = np.concatenate(owners), np.concatenate(pixels)
    if not pixel.size:
        return [[] for _ in grasps]
    across = np.concatenate(acrosses) / edge
    # Darkening at full width: contrast, tapered over the edge at the strip's ends.
    depth = -contrast[owner] * np.clip((half_length[owner] - np.concatenate(alongs)) / edge, 0, 1)
    b_edge = np.ascontiguousarray(width_px.T) / edge  # (S + 1, n grasps)

    def log_intensity(first: int, stop: int) -> Tensor:  # (stop - first, P) levels, rounded to LOG_QUANTUM
        cover = b_edge[first:stop][:, owner]
        cover -= across
        np.clip(cover, 0.0, 1.0, out=cover)
        level = np.log1p(np.multiply(depth, cover, out=cover), out=cover)
        level *= 1.0 / LOG_QUANTUM
        return torch.from_numpy(np.round(level, out=level)).to(torch.float32).mul_(LOG_QUANTUM)

    steps = width_px.shape[1]
    times = torch.arange(steps, dtype=torch.float64) * (config.substep_ms * 1000.0)
    on_active, off_active = on[0, torch.from_numpy(pixel)], off[0, torch.from_numpy(pixel)]
    chunk = max(1, _CHUNK_LEVELS // pixel.size)
    state = None
    columns, stamps, polarities = [], [], []
    for first in range(0, steps - 1, chunk):  # pieces of `chunk` intervals (bounded memory)
        stop = min(steps, first + chunk + 1)
        (_, column, t, p), state = threshold_crossings(
            log_intensity(first, stop), times[first:stop], on_active, off_active,
            refractory_us=config.refractory_us, state=state,
        )
        columns.append(column)
        stamps.append(torch.floor(t).to(torch.int64))
        polarities.append(p)
    fired = torch.cat(columns).numpy()
    t_us = torch.cat(stamps).numpy()
    # a crossing at the last substep's very end (t = duration) is after the recording [0, duration)
    inside = t_us < int(round(config.duration_ms * 1000))
    fired = fired[inside]
    return _by_owner(owner[fired], pixel[fired], t_us[inside], torch.cat(polarities).numpy()[inside], len(grasps))


def simulate_grasps(grasps: Sequence[Grasp], config: SimulatorConfig | None = None) -> list[Recording]:
    """Simulate several grasps at once (vectorised over all of their pixels).

    Args:
        grasps: experiments from :func:`draw_grasp` (made with the same ``config``).
        config: simulator settings (defaults to :class:`SimulatorConfig()`).

    Returns:
        One :class:`Recording` per grasp, in order.

    Example:
        >>> config = SimulatorConfig()
        >>> grasps = [draw_grasp(d, seed=s, config=config) for d, s in [(12.0, 0), (18.0, 1)]]
        >>> [r.force.shape for r in simulate_grasps(grasps, config)]
        [(36,), (36,)]
    """
    config = config or SimulatorConfig()
    grasps = list(grasps)
    height, width = config.sensor_size
    duration_us = int(round(config.duration_ms * 1000))
    frame_times_ms = (np.arange(config.n_frames) + 0.5) * config.frame_ms
    if config.label_lowpass_ms > 0 and grasps:
        force = _label_force(grasps, frame_times_ms, config)
    else:
        force = force_profile(grasps, frame_times_ms, config).astype(np.float32)
    contact: list = [[] for _ in grasps]
    if config.contact and grasps:
        steps = int(round(config.duration_ms / config.substep_ms))
        fine_ms = np.arange(steps + 1) * config.substep_ms
        delay = np.array([g.delay_ms for g in grasps])[:, None]
        fine = force_profile(grasps, fine_ms[None, :] - delay, config)
        lag = np.array([g.lag_ms for g in grasps])
        lagged = (
            membrane_force(fine, lag, config.substep_ms, release_ratio=config.release_lag_ratio) if config.lag else fine
        )
        diameter = np.array([g.diameter_mm for g in grasps])[:, None]
        b = contact_half_width(lagged, diameter, config)
        contact = _contact_events(grasps, b, config)
    force_t_us = np.round(frame_times_ms * 1000).astype(np.int64)
    background = _background([g.seed for g in grasps], duration_us, config)
    return [
        Recording(
            events=_to_events(contact[i] + background[i], config.sensor_size),
            force=force[i],
            force_t_us=force_t_us,
            grasp=g,
            config=config,
        )
        for i, g in enumerate(grasps)
    ]


def _label_force(grasps: Sequence[Grasp], frame_times_ms: np.ndarray, config: SimulatorConfig) -> np.ndarray:
    """The F/T sensor's reading at the frame centres: the force through a first-order
    low-pass of time constant ``label_lowpass_ms`` (on a 0.1 ms grid from rest)."""
    step = 0.1
    fine_ms = np.arange(int(round(config.duration_ms / step)) + 1) * step
    fine = force_profile(grasps, fine_ms, config)
    smooth = membrane_force(fine, np.full(len(grasps), config.label_lowpass_ms), step)
    index = np.round(frame_times_ms / step).astype(np.int64)
    return smooth[:, index].astype(np.float32)


def simulate_grasp(
    diameter_mm: float, *, gripper: int = 0, seed: int = 0, config: SimulatorConfig | None = None
) -> Recording:
    """Simulate one grasp of a bolt of ``diameter_mm`` (see the module docstring).

    Example:
        >>> recording = simulate_grasp(12.0, gripper=1, seed=0)
        >>> recording.events.dtype.names, recording.force.shape
        (('x', 'y', 't', 'p'), (36,))
        >>> recording.frames(crop=recording.contact_crop(), pool=2).shape
        torch.Size([36, 2, 70, 75])
    """
    config = config or SimulatorConfig()
    return simulate_grasps([draw_grasp(diameter_mm, gripper=gripper, seed=seed, config=config)], config)[0]


def simulate_static(
    duration_ms: float, *, seed: int = 0, config: SimulatorConfig | None = None
) -> np.ndarray:
    """Events of a static scene (no contact): background shot noise and hot pixels only.

    Args:
        duration_ms: length of the recording.
        seed: seed of the noise realisation (the camera's pixels come from
            ``config.sensor_seed``).
        config: simulator settings (defaults to :class:`SimulatorConfig()`).

    Returns:
        Structured array (:data:`EVENT_DTYPE`) sorted by time, t in [0, duration).

    Example:
        >>> events = simulate_static(100.0, seed=0)
        >>> bool((events["t"] < 100_000).all()), events.dtype.names
        (True, ('x', 'y', 't', 'p'))
    """
    config = config or SimulatorConfig()
    if not (isinstance(duration_ms, (int, float)) and duration_ms > 0 and math.isfinite(duration_ms)):
        raise ValueError(f"duration_ms must be a positive number, got {duration_ms!r}")
    duration_us = int(round(duration_ms * 1000))
    return _to_events(_background([seed], duration_us, config)[0], config.sensor_size)
