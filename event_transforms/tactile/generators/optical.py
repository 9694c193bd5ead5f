"""The optical generator: an event-based GelSight rendered from a real sensor's calibration.

The built-in simulator (:mod:`event_transforms.tactile.simulation`) draws the contact as a
dark strip whose every change is the inverse of some augmentation. This generator uses
physics this project did not write: ``taxim`` (the Taxim optical model, MIT; ``pip install
'event-transforms[optical]'``) renders the gel of a GelSight Mini, with its measured
calibration and coloured, directional light, for an object's height map pressed to a depth.
One grasp, drawn by :func:`~event_transforms.tactile.simulation.draw_grasp` exactly as for the
built-in generator (same force, timing, delay, membrane time constant, angle, centre):

1. **Object.** :class:`OpticalObject`: a cylinder (bolt shank) of diameter D lying across the
   pad, with rounded ends (``contact_length_mm`` 8 mm of shank, end radius 2 mm), or a hex bolt head
   pressed flat (``"hex"``, across-flats D, a 45° chamfer around it). Its height map is
   rotated by the grasp's angle (the built-in convention: counter-clockwise in the image,
   0° = along the sensor's x axis) and rendered at the nearest ``angle_step_deg`` (2.5°).
2. **Contact law** (:func:`press_depth`): the gel is a thin elastic layer on a rigid backing
   (a Winkler foundation: pressure = k·local indentation, k = E*/h = 1 N/mm³ for E* = 2 MPa,
   h = 2 mm). A cylinder of radius R over a contact length L pressed δ deep carries
   F = (4/3)·k·L·√(2R)·δ^(3/2) (so its strip half-width √(2Rδ) grows as (F·R)^⅓, the thin-layer
   exponent); a flat hex face of area A = (√3/2)·D² carries F = k·A·δ.
3. **Membrane** (:func:`membrane_depth`): a standard linear solid (Zener) on the depth, in
   the quasi-linear form of Fung: the elastic depth δ_e(t) = law(F(t − delay)) passes through
   the creep function J(t) ∝ r + (1 − r)(1 − e^(−t/τ)), i.e. δ = r·δ_e + (1 − r)·lag_τ(δ_e)
   with an instantaneous fraction r = ½ and the session's τ (``lag_ms``) and release ratio
   (``release_lag_ratio``) from :class:`~event_transforms.tactile.simulation.SimulatorConfig`.
4. **Rendering** (:func:`render_table`): per object and angle node a table of the gel's
   luminance over depth (``depth_step_mm`` 0.04 mm to ``max_depth_mm`` 0.8 mm), rendered once
   with taxim's shadows (``OpticalConfig.shadows``, since version 3; none before) at 240×320
   (``render_scale`` 2 of the calibration's 480×640, 0.059 mm/px),
   converted to luminance by ``OpticalConfig.channel``: the red channel by default (one
   coloured light; since version 2, chosen against the recorded GelSight Wedge grasps by
   ``benchmarks/tactile/recorded_vs_generators.py``: at peak force the red render changes the log
   luminance by 0.72-2.18, median 1.39, the recorded sensor by 0.70-1.39, median 0.93, and
   events per frame follow |dF/dt| with r +0.82 against +0.73 recorded, where Rec. 601 luma,
   the version-1 camera, mixed the gel's directional shading away: 0.04-0.12 and +0.27; since
   version 3 with taxim's shadows and the threshold 0.07, the closest camera by the stated rule of
   that script: 1.06 at peak, 2.85 % of the pixels firing at peak (3.04 % recorded) and r +0.73
   against |dF/dt| (+0.73 recorded)) and
   area-resampled onto the sensor grid (180×240: the 14.2 × 18.9 mm field, 0.079 mm per
   pixel). Tables are cached on disk (content-keyed: taxim's version, the calibration files,
   the object, angle, depths and grids; written atomically; an unreadable file is named in a
   warning and rebuilt) and at most ``table_memory_mb`` of them are held in memory.
   In time the luminance is interpolated linearly between depth nodes on the 1 ms grid. The
   grasp's centre offset moves the contact image by whole sensor pixels over the fixed
   illumination (the background stays).
5. **Events**: the luminance of every 1 ms substep into the library's DVS emulator
   (:func:`~event_transforms.functional.emulate_events`: v2e's lin-log response, the log
   intensity linear between substeps): the session's camera (thresholds with mismatch,
   refractory period, shot noise, hot pixels; its pixel properties from ``sensor_seed``, the
   recording's noise from the grasp's seed) and leak events at ``leak_hz`` 0.1 Hz (from a
   reset reference a pixel's first leak event comes after 1 / leak_hz = 10 s, so a 360 ms
   grasp has none unless ``random_reference``). Since ``OPTICAL_VERSION`` 2 (the library's
   counter-based draws, crossing times by interpolation, a continuous refractory period,
   hot pixels drawn per pixel, the red channel) a seed gives other events than version 1's
   numpy model; version 3 (shadows) other events than version 2's; version 4 renders on XLA's
   single-threaded CPU kernels (:data:`REPRODUCIBLE_XLA_FLAGS`: version 3's multi-threaded render
   gave another image on some calls, so its cached tables were not what their keys said). The optical scenes' camera has
   the threshold 0.07 (:data:`~event_transforms.tactile.benchmark_scenes.OPTICAL_BASE_SESSION`; 0.05 in
   versions 1 and 2), chosen with the shadows by the same comparison. taxim's own
   rendering artefacts (faint rings from its binned gradient lookup) are part of the image and
   fire events too.

The output is the built-in generator's :class:`~event_transforms.tactile.simulation.Recording`,
so binning, data sets and the protocol are unchanged. Settings of the built-in contact strip
(``width_exponent``, ``reference_half_width_px``, ``strip_half_length_px``, ``edge_px``,
``contrast`` and the size-model exponents) do not apply here; ``label_lowpass_ms`` is refused.
Results on this data are results on synthetic data, never the paper's.
"""

from __future__ import annotations

__all__ = [
    "OPTICAL_VERSION",
    "OpticalConfig",
    "OpticalObject",
    "height_map",
    "press_depth",
    "membrane_depth",
    "render_table",
    "taxim_renderer",
    "simulate_optical",
    "REPRODUCIBLE_XLA_FLAGS",
    "RenderNotReproducibleWarning",
]

import functools
import hashlib
import json
import math
import os
import sys
import warnings
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..simulation import EVENT_DTYPE, Grasp, Recording, SimulatorConfig, force_profile, membrane_force
from .._files import atomic_write
from ...functional.emulate import emulate_events

#: Bumped whenever the generator changes what a seed produces (keys the caches). Version 4:
#: taxim's render on XLA's single-threaded CPU kernels (:data:`REPRODUCIBLE_XLA_FLAGS`), so that a
#: table is what its key says; version 3's multi-threaded render gave another image on some calls.
OPTICAL_VERSION = 4

#: The XLA settings under which taxim's JAX render is reproducible on the CPU. With XLA's
#: multi-threaded CPU kernels (Eigen's thread pool) one 21-map table rendered six times in a fresh
#: process beside two busy ones gave 3 distinct images, up to 0.061 apart: version 3's cached tables
#: under one key differed between processes. Single-threaded, every call gives the same image, and on
#: the 2-core machine no slower (3.54 s a render against 3.46; ``benchmarks/tactile/optical_render.py``). :func:`taxim_renderer` adds them to ``XLA_FLAGS`` when JAX has
#: not started yet: JAX on the CPU then runs single-threaded in that process.
REPRODUCIBLE_XLA_FLAGS = ("--xla_cpu_multi_thread_eigen=false", "intra_op_parallelism_threads=1")


class RenderNotReproducibleWarning(UserWarning):
    """taxim's render runs with XLA's multi-threaded CPU kernels, so a table may differ between calls.

    Raised when JAX had started before the optical generator could set
    :data:`REPRODUCIBLE_XLA_FLAGS`, or when ``XLA_FLAGS`` sets one of them to another value. Set
    ``XLA_FLAGS="--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"`` before JAX
    starts (before the process's first JAX computation).
    """

#: A renderer: (N, H, W) height maps in mm, already pressed (contact where <= 0) -> (N, H, W, 3) RGB in [0, 1].
Renderer = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class OpticalConfig:
    """Settings of the optical generator (see the module docstring).

    Attributes:
        calibration: taxim's calibration folder name (``"gelsight_mini"`` or ``"gelsight"``).
        calibration_size: (H, W) of that calibration's images.
        calibration_mm_per_px: its pixel size in mm.
        render_scale: render at ``calibration_size / render_scale`` (pixel size × scale).
        foundation_n_per_mm3: the gel layer's foundation modulus k = E*/h.
        contact_length_mm: the cylinder's shank length pressed into the gel.
        end_radius_mm: radius of the shank's rounded ends.
        instant_fraction: r, the SLS's instantaneous share of the depth (0 < r <= 1).
        depth_step_mm, max_depth_mm: the render table's depth nodes.
        angle_step_deg: the render table's angle nodes (angles are rounded to them).
        leak_hz: DVS leak-event rate.
        random_reference: each pixel's reference starts a uniform random fraction of its ON
            threshold below its level (v2e; the steady state of a leaky pixel under constant
            light); ``False`` (default): at its level, a pixel reset at the start of the
            recording, as in the built-in simulator. With ``True`` a small brightening fires ON
            events that the matching darkening does not undo, and the physics least-squares
            model's test MSE on ``optical-control`` doubled (18.0 vs 10.0 N², 60 + 40 grasps).
        table_memory_mb: the most render-table memory held at once.
        channel: how the rendered RGB becomes the DVS's luminance: 0, 1, 2 (one colour
            channel: R, G, B; 0, red, by default: see the module docstring), ``"luma"`` (Rec.
            601, a monochrome sensor: version 1's camera) or ``"mean"``.
        shadows: render with taxim's shadows (``with_shadow``: the object's cast shadows of
            each light); on by default since version 3 (see the module docstring), off before.
    """

    calibration: str = "gelsight_mini"
    calibration_size: tuple[int, int] = (480, 640)
    calibration_mm_per_px: float = 0.0295
    render_scale: int = 2
    foundation_n_per_mm3: float = 1.0
    contact_length_mm: float = 8.0
    end_radius_mm: float = 2.0
    instant_fraction: float = 0.5
    depth_step_mm: float = 0.04
    max_depth_mm: float = 0.8
    angle_step_deg: float = 2.5
    leak_hz: float = 0.1
    table_memory_mb: float = 256.0
    random_reference: bool = False
    channel: str | int = 0
    shadows: bool = True

    def __post_init__(self) -> None:
        if not isinstance(self.shadows, bool):
            raise TypeError(f"shadows must be a bool, got {self.shadows!r}")
        if self.channel not in ("luma", "mean", 0, 1, 2) or isinstance(self.channel, bool):
            raise ValueError(f"channel must be 'luma', 'mean' or 0, 1, 2, got {self.channel!r}")
        if isinstance(self.render_scale, bool) or not isinstance(self.render_scale, int) or self.render_scale < 1:
            raise ValueError(f"render_scale must be a positive integer, got {self.render_scale!r}")
        for name in ("foundation_n_per_mm3", "contact_length_mm", "end_radius_mm", "depth_step_mm",
                     "max_depth_mm", "angle_step_deg", "table_memory_mb", "calibration_mm_per_px"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and value > 0 and math.isfinite(value)):
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        if not 0 < self.instant_fraction <= 1:
            raise ValueError(f"instant_fraction must lie in (0, 1], got {self.instant_fraction!r}")
        if not (self.leak_hz >= 0 and math.isfinite(self.leak_hz)):
            raise ValueError(f"leak_hz must be non-negative, got {self.leak_hz!r}")

    @property
    def render_size(self) -> tuple[int, int]:
        """(H, W) of the rendered images."""
        return self.calibration_size[0] // self.render_scale, self.calibration_size[1] // self.render_scale

    @property
    def mm_per_px(self) -> float:
        """Pixel size of the rendered images, mm."""
        return self.calibration_mm_per_px * self.render_scale

    @property
    def depths_mm(self) -> np.ndarray:
        """The render table's depth nodes, 0 ... ``max_depth_mm``."""
        return np.arange(int(round(self.max_depth_mm / self.depth_step_mm)) + 1) * self.depth_step_mm


@dataclass(frozen=True)
class OpticalObject:
    """An object pressed into the gel: ``"cylinder"`` (diameter ``size_mm``, lying across the
    pad) or ``"hex"`` (a hex bolt head, ``size_mm`` across flats, pressed flat)."""

    kind: str
    size_mm: float

    def __post_init__(self) -> None:
        if self.kind not in ("cylinder", "hex"):
            raise ValueError(f"kind must be 'cylinder' or 'hex', got {self.kind!r}")
        if not (isinstance(self.size_mm, (int, float)) and self.size_mm > 0 and math.isfinite(self.size_mm)):
            raise ValueError(f"size_mm must be a positive number, got {self.size_mm!r}")


def height_map(obj: OpticalObject, angle_deg: float, config: OpticalConfig | None = None) -> np.ndarray:
    """The object's surface above its lowest point (mm) over the render grid, turned by ``angle_deg``.

    Args:
        obj: the object.
        angle_deg: its angle, counter-clockwise in the image (0: a cylinder along x).
        config: the render grid (``render_size``, ``mm_per_px``) and the cylinder's length.

    Example:
        >>> config = OpticalConfig(render_scale=8)
        >>> hm = height_map(OpticalObject("cylinder", 15.0), 0.0, config)
        >>> hm.shape, float(hm.min()), bool(hm[30, 40] < hm[0, 40])
        ((60, 80), 0.0, True)
    """
    config = config or OpticalConfig()
    h, w = config.render_size
    y, x = np.mgrid[:h, :w].astype(np.float64)
    dy, dx = (y - (h - 1) / 2) * config.mm_per_px, (x - (w - 1) / 2) * config.mm_per_px
    theta = np.deg2rad(angle_deg)
    across = dx * np.sin(theta) + dy * np.cos(theta)
    along = dx * np.cos(theta) - dy * np.sin(theta)
    if obj.kind == "cylinder":
        radius = obj.size_mm / 2
        u = np.minimum(np.abs(across), radius)
        surface = radius - np.sqrt(radius**2 - u**2) + (np.abs(across) - u)
        beyond = np.maximum(np.abs(along) - config.contact_length_mm / 2, 0.0)
        surface = surface + beyond**2 / (2 * config.end_radius_mm)
    else:
        apothem = obj.size_mm / 2
        outside = np.zeros_like(dx)
        for k in range(3):  # the hexagon's three pairs of flats
            phi = theta + k * np.pi / 3
            outside = np.maximum(outside, np.abs(dx * np.sin(phi) + dy * np.cos(phi)) - apothem)
        surface = outside  # a 45° chamfer around the flat face
    return (surface - surface.min()).astype(np.float32)


def press_depth(force_n: np.ndarray | float, obj: OpticalObject, config: OpticalConfig | None = None) -> np.ndarray:
    """Depth (mm) at which the object carries ``force_n`` on the gel's Winkler foundation.

    Cylinder: F = (4/3)·k·L·√(2R)·δ^(3/2); hex face: F = k·A·δ with A = (√3/2)·D².

    Args:
        force_n: forces, newtons (finite, non-negative).
        obj: the object.
        config: the foundation modulus k and the cylinder's contact length L.

    Example:
        >>> obj = OpticalObject("cylinder", 15.0)
        >>> depth = float(press_depth(25.0, obj))
        >>> round(depth, 4), round(4 / 3 * 8.0 * math.sqrt(15.0) * depth**1.5, 6)
        (0.7154, 25.0)
    """
    config = config or OpticalConfig()
    force = np.asarray(force_n, dtype=np.float64)
    if np.any(force < 0) or not np.all(np.isfinite(force)):
        raise ValueError(f"force_n must be finite and non-negative, got min {float(np.min(force))!r}")
    k = config.foundation_n_per_mm3
    if obj.kind == "cylinder":
        stiffness = 4.0 / 3.0 * k * config.contact_length_mm * math.sqrt(obj.size_mm)  # √(2R) = √D
        return (force / stiffness) ** (2.0 / 3.0)
    return force / (k * math.sqrt(3) / 2 * obj.size_mm**2)


def membrane_depth(
    elastic_depth: np.ndarray, lag_ms: np.ndarray, step_ms: float, *, instant_fraction: float,
    release_ratio: float = 1.0,
) -> np.ndarray:
    """The standard linear solid on the depth: ``r·δ_e + (1 − r)·lag_τ(δ_e)`` per row.

    ``elastic_depth`` (n, S) on a uniform grid of ``step_ms``, starting at rest; ``lag_ms``
    (n,) the creep time constants τ (the lag is
    :func:`~event_transforms.tactile.simulation.membrane_force`, exact for a depth linear
    between grid points; ``release_ratio`` slows it while the gel relaxes).

    Args:
        elastic_depth: (n, S) the contact law's depth of the force at each grid point.
        lag_ms: (n,) creep time constants τ.
        step_ms: grid step.
        instant_fraction: r, the instantaneous share.
        release_ratio: τ multiplier while the depth falls below the membrane's.

    Example:
        >>> ramp = np.arange(101)[None, :] * 0.01  # 0.01 mm per ms
        >>> out = membrane_depth(ramp, np.array([10.0]), 1.0, instant_fraction=0.5)
        >>> expected = 0.01 * (100 - 0.5 * 10 * (1 - math.exp(-100 / 10)))
        >>> round(float(out[0, -1]), 9) == round(expected, 9)
        True
    """
    lagged = membrane_force(elastic_depth, lag_ms, step_ms, release_ratio=release_ratio)
    return instant_fraction * np.asarray(elastic_depth, dtype=np.float64) + (1.0 - instant_fraction) * lagged


# --------------------------------------------------------------------------- rendering


@functools.lru_cache(maxsize=2)
def _calibration(name: str) -> tuple[Path, str]:
    """taxim's calibration folder and a hash of its files' contents."""
    try:
        import taxim
        from taxim import calibration
    except ImportError as error:
        raise ImportError(
            "the optical generator needs taxim and jax: pip install 'event-transforms[optical]'"
        ) from error
    folder = Path(calibration.CALIB_ROOT) / name
    if not folder.is_dir():
        raise ValueError(f"calibration must name a folder of {calibration.CALIB_ROOT}, got {name!r}")
    digest = hashlib.sha256(getattr(taxim, "__version__", "").encode())
    for path in sorted(folder.iterdir()):
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    return folder, digest.hexdigest()[:16]


def _jax_started() -> bool:
    """Whether JAX's backends exist in this process (``XLA_FLAGS`` is read when they start)."""
    if "jax" not in sys.modules:
        return False
    try:
        from jax._src import xla_bridge

        return bool(xla_bridge.backends_are_initialized())
    except (ImportError, AttributeError):  # another JAX: assume it started
        return True


def _reproducible_xla() -> None:
    """Add :data:`REPRODUCIBLE_XLA_FLAGS` to ``XLA_FLAGS`` before JAX starts, else warn by name."""
    flags = os.environ.get("XLA_FLAGS", "").split()
    given = {flag.split("=", 1)[0]: flag for flag in flags}
    wanted = {flag.split("=", 1)[0]: flag for flag in REPRODUCIBLE_XLA_FLAGS}
    missing = [flag for name, flag in wanted.items() if given.get(name) != flag]
    if not missing:
        return
    conflicting = [given[name] for name, flag in wanted.items() if name in given and given[name] != flag]
    if conflicting:
        reason = f"XLA_FLAGS sets {' '.join(conflicting)}"
    elif _jax_started():
        reason = "JAX started before the optical generator could set XLA_FLAGS"
    else:
        os.environ["XLA_FLAGS"] = " ".join([*flags, *missing])
        return
    warnings.warn(RenderNotReproducibleWarning(
        f"{reason}: taxim's render runs with XLA's multi-threaded CPU kernels and may give another table on "
        f"another call; set XLA_FLAGS={' '.join(REPRODUCIBLE_XLA_FLAGS)!r} before JAX starts"), stacklevel=3)


@functools.lru_cache(maxsize=2)
def _taxim(name: str, mm_per_px: float) -> object:
    _reproducible_xla()
    from taxim import Taxim

    folder, _ = _calibration(name)
    return Taxim(calib_folder=folder, params={"sensor": {"pixmm": mm_per_px}}, backend="jax")


def taxim_renderer(config: OpticalConfig | None = None) -> Renderer:
    """taxim's JAX renderer for ``config``'s calibration and render grid (shadows if ``config.shadows``).

    Args:
        config: the calibration and the render grid (its pixel size is handed to taxim).

    Before JAX starts, adds :data:`REPRODUCIBLE_XLA_FLAGS` to ``XLA_FLAGS`` (XLA's single-threaded
    CPU kernels: the same maps give the same image on every call); when JAX has started without
    them, warns with :class:`RenderNotReproducibleWarning`. The maps are rendered in one batch:
    taxim's image of a map depends on the batch it is rendered in (single-threaded too), so a table
    is always rendered whole.

    Returns:
        ``pressed (N, H, W) mm -> RGB (N, H, W, 3)``: contact where the map is <= 0.

    Example:
        >>> render = taxim_renderer(OpticalConfig(render_scale=16))
        >>> pressed = height_map(OpticalObject("cylinder", 15.0), 0.0, OpticalConfig(render_scale=16))[None] - 0.3
        >>> render(pressed).shape
        (1, 30, 40, 3)

    Raises:
        ImportError: taxim or jax is missing (``pip install 'event-transforms[optical]'``).

    Warns:
        RenderNotReproducibleWarning: JAX started without :data:`REPRODUCIBLE_XLA_FLAGS`.
    """
    config = config or OpticalConfig()
    simulator = _taxim(config.calibration, config.mm_per_px)
    shadows = config.shadows

    def render(pressed: np.ndarray) -> np.ndarray:
        # press_depth=None: the maps are already pressed (contact where <= 0).
        return np.asarray(simulator.render(np.asarray(pressed, np.float32), with_shadow=shadows, press_depth=None))  # type: ignore[attr-defined]

    return render


def _luminance(rgb: np.ndarray, sensor_size: tuple[int, int], channel: str | int = 0) -> np.ndarray:
    """The ``channel`` luminance of (N, h, w, 3) RGB (red by default), area-resampled to (N, H, W) float32."""
    weights = {"luma": (0.299, 0.587, 0.114), "mean": (1 / 3, 1 / 3, 1 / 3), 0: (1.0, 0.0, 0.0), 1: (0.0, 1.0, 0.0),
               2: (0.0, 0.0, 1.0)}[channel]
    luma = rgb[..., 0] * weights[0] + rgb[..., 1] * weights[1] + rgb[..., 2] * weights[2]
    tensor = torch.from_numpy(np.ascontiguousarray(luma, dtype=np.float32))[:, None]
    return torch.nn.functional.interpolate(tensor, size=sensor_size, mode="area")[:, 0].numpy()


def _table_key(obj: OpticalObject, angle_deg: float, config: OpticalConfig, sensor_size: tuple[int, int],
               calibration_hash: str) -> str:
    settings = asdict(config)
    for unused in ("leak_hz", "table_memory_mb", "instant_fraction", "foundation_n_per_mm3", "random_reference"):
        settings.pop(unused)  # they do not change a table
    if not settings["shadows"]:
        settings.pop("shadows")  # the key of every table rendered before the option existed
    description = {
        "version": OPTICAL_VERSION, "calibration": calibration_hash, "object": asdict(obj),
        "angle_deg": round(float(angle_deg), 6), "config": settings, "sensor_size": list(sensor_size),
    }
    return json.dumps(description, sort_keys=True)


class _TableMemory:
    """The render tables held in memory, least recently used dropped beyond a byte budget."""

    def __init__(self) -> None:
        self.tables: OrderedDict[str, np.ndarray] = OrderedDict()

    def get(self, key: str) -> np.ndarray | None:
        table = self.tables.get(key)
        if table is not None:
            self.tables.move_to_end(key)
        return table

    def put(self, key: str, table: np.ndarray, budget_mb: float) -> None:
        self.tables[key] = table
        while len(self.tables) > 1 and sum(t.nbytes for t in self.tables.values()) > budget_mb * 2**20:
            self.tables.popitem(last=False)


_MEMORY = _TableMemory()


def _read_table(path: Path, key: str, shape: tuple[int, ...]) -> np.ndarray | None:
    if not path.exists():
        return None
    try:
        with np.load(path, allow_pickle=False) as stored:
            if str(stored["key"]) != key:
                raise ValueError("its key does not match its name")
            table = np.array(stored["luminance"], dtype=np.float32)
        if table.shape != shape or not np.isfinite(table).all():
            raise ValueError(f"luminance of shape {table.shape}, expected {shape}")
        return table
    except Exception as error:  # noqa: BLE001 - any unreadable table is rebuilt, by name
        warnings.warn(f"discarded the unreadable render table {path} ({type(error).__name__}: {error}); "
                      "rebuilding it", stacklevel=4)
        path.unlink(missing_ok=True)
        return None


def _write_table(path: Path, key: str, table: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(path, "wb") as stream:  # the application's one atomic writer
        np.savez(stream, key=np.array(key), luminance=table)


def render_table(
    obj: OpticalObject,
    angle_deg: float,
    sensor_size: tuple[int, int] = (180, 240),
    config: OpticalConfig | None = None,
    *,
    root: str | os.PathLike[str] | None = None,
    renderer: Renderer | None = None,
) -> np.ndarray:
    """The gel's luminance on the sensor grid at every depth node: float32 ``(K + 1, H, W)``.

    Cached in ``root`` (default :func:`~event_transforms.tactile.datasets.default_cache_dir`)
    as ``optical-table-v<version>-<hash>.npz``, the hash over everything that determines the
    table (taxim's version and calibration files included); an unreadable file is named in a
    warning, deleted and rebuilt. ``renderer`` (default :func:`taxim_renderer`) is only
    called on a cache miss.

    Args:
        obj: the object.
        angle_deg: its angle (a table per angle).
        sensor_size: (H, W) of the sensor grid.
        config: the generator's settings (render grid, depth nodes, memory budget).
        root: cache folder.
        renderer: render function for a cache miss.

    Example:
        >>> import tempfile
        >>> fake = lambda maps: np.repeat(np.clip(0.5 + maps, 0, 1)[..., None], 3, axis=-1)
        >>> config = OpticalConfig(render_scale=8, max_depth_mm=0.16)
        >>> table = render_table(OpticalObject("cylinder", 15.0), 0.0, (30, 40), config,
        ...                      root=tempfile.mkdtemp(), renderer=fake)
        >>> table.shape, bool(table[-1].min() < table[0].min())
        ((5, 30, 40), True)
    """
    config = config or OpticalConfig()
    sensor_size = (int(sensor_size[0]), int(sensor_size[1]))
    if renderer is None:
        _, calibration_hash = _calibration(config.calibration)
    else:
        calibration_hash = f"renderer:{getattr(renderer, '__qualname__', type(renderer).__name__)}"
    key = _table_key(obj, angle_deg, config, sensor_size, calibration_hash)
    held = _MEMORY.get(key)
    if held is not None:
        return held
    if root is None:
        from .._files import default_cache_dir

        root = default_cache_dir()
    path = Path(root) / f"optical-table-v{OPTICAL_VERSION}-{hashlib.sha256(key.encode()).hexdigest()[:16]}.npz"
    depths = config.depths_mm
    table = _read_table(path, key, (depths.size, *sensor_size))
    if table is None:
        surface = height_map(obj, angle_deg, config)
        pressed = surface[None, :, :] - depths[:, None, None].astype(np.float32)
        rgb = (renderer or taxim_renderer(config))(pressed)
        table = _luminance(rgb, sensor_size, config.channel)
        _write_table(path, key, table)
    table.setflags(write=False)
    _MEMORY.put(key, table, config.table_memory_mb)
    return table


# --------------------------------------------------------------------------- events


def _shifted(delta: np.ndarray, dy: int, dx: int) -> np.ndarray:
    """``delta`` (K, H, W) moved by whole pixels, zero-filled."""
    out = np.zeros_like(delta)
    h, w = delta.shape[1:]
    out[:, max(dy, 0):h + min(dy, 0), max(dx, 0):w + min(dx, 0)] = delta[
        :, max(-dy, 0):h + min(-dy, 0), max(-dx, 0):w + min(-dx, 0)
    ]
    return out


def simulate_optical(
    grasps: Sequence[Grasp],
    config: SimulatorConfig | None = None,
    optical: OpticalConfig | None = None,
    *,
    kind: str = "cylinder",
    root: str | os.PathLike[str] | None = None,
    renderer: Renderer | None = None,
) -> list[Recording]:
    """Simulate grasps with the optical generator (see the module docstring).

    Args:
        grasps: experiments from :func:`~event_transforms.tactile.simulation.draw_grasp`
            (their diameter is the object's size).
        config: the session's settings (force, timing, membrane, angle, camera).
        optical: the optical generator's settings.
        kind: the object, ``"cylinder"`` or ``"hex"``.
        root: render-table cache folder (default the data sets' cache folder).
        renderer: render function (default :func:`taxim_renderer`; only called on a cache miss).

    Returns:
        One :class:`~event_transforms.tactile.simulation.Recording` per grasp.

    Example:
        >>> import tempfile
        >>> from event_transforms.tactile.simulation import draw_grasp
        >>> fake = lambda maps: np.repeat(np.clip(0.5 + maps, 0, 1)[..., None], 3, axis=-1)
        >>> config = SimulatorConfig(sensor_size=(30, 40), center_jitter_px=1.0)
        >>> small = OpticalConfig(render_scale=8)
        >>> recording = simulate_optical([draw_grasp(15.0, seed=0, config=config)], config, small,
        ...                              root=tempfile.mkdtemp(), renderer=fake)[0]
        >>> recording.force.shape, bool(len(recording.events) > 0)
        ((36,), True)
    """
    config = config or SimulatorConfig()
    optical = optical or OpticalConfig()
    if config.label_lowpass_ms > 0:
        raise ValueError(f"label_lowpass_ms is not supported by the optical generator, got {config.label_lowpass_ms!r}")
    grasps = list(grasps)
    height, width = config.sensor_size
    duration_us = int(round(config.duration_ms * 1000))
    frame_times_ms = (np.arange(config.n_frames) + 0.5) * config.frame_ms
    force = force_profile(grasps, frame_times_ms, config).astype(np.float32) if grasps else np.zeros((0, config.n_frames))
    steps = int(round(config.duration_ms / config.substep_ms))
    fine_ms = np.arange(steps + 1) * config.substep_ms
    dt_us = config.substep_ms * 1000.0
    camera = _emulator_camera(config, optical)
    recordings = []
    for index, grasp in enumerate(grasps):
        if config.contact:
            obj = OpticalObject(kind, grasp.diameter_mm)
            elastic = press_depth(force_profile([grasp], fine_ms - grasp.delay_ms, config), obj, optical)
            depth = elastic
            if config.lag and grasp.lag_ms > 0:
                depth = membrane_depth(elastic, np.array([grasp.lag_ms]), config.substep_ms,
                                       instant_fraction=optical.instant_fraction, release_ratio=config.release_lag_ratio)
            depth = depth[0]
            if depth.max() > optical.max_depth_mm:
                raise ValueError(f"grasp {grasp.seed} presses {depth.max():.3f} mm deep, beyond max_depth_mm "
                                 f"({optical.max_depth_mm}); raise max_depth_mm or lower the forces")
            node = round(grasp.angle_deg / optical.angle_step_deg) * optical.angle_step_deg
            table = render_table(obj, node, config.sensor_size, optical, root=root, renderer=renderer)
            center = ((height - 1) / 2, (width - 1) / 2)
            dy, dx = (int(round(grasp.center_yx[k] - center[k])) for k in range(2))
            delta = _shifted(table - table[0], dy, dx).astype(np.float32)
            position = np.minimum(depth / optical.depth_step_mm, table.shape[0] - 1.0)
            lower = np.minimum(np.floor(position).astype(np.int64), table.shape[0] - 2)
            fraction = (position - lower).astype(np.float32)[:, None, None]
            # the luminance of every substep, linear between depth nodes: the emulator's frames
            luminance = table[0].astype(np.float32) + delta[lower]
            luminance += fraction * (delta[lower + 1] - delta[lower])
            times = np.arange(steps + 1) * dt_us
        else:  # constant light: leak and background only
            luminance = np.full((2, height, width), 0.5)
            times = np.array([0.0, float(duration_us)])
        events = emulate_events(
            torch.from_numpy(np.asarray(luminance, dtype=np.float32)), frame_times_us=torch.from_numpy(times),
            seed=_recording_seed(grasp.seed), camera_seed=config.sensor_seed, **camera,
        )
        out = np.empty(events.num_events, dtype=EVENT_DTYPE)
        for column in ("x", "y", "t", "p"):
            out[column] = getattr(events, column).numpy()
        recordings.append(Recording(events=out, force=force[index],
                                    force_t_us=np.round(frame_times_ms * 1000).astype(np.int64), grasp=grasp,
                                    config=config))
    return recordings


def _emulator_camera(config: SimulatorConfig, optical: OpticalConfig) -> dict[str, Any]:
    """The session's camera as :func:`~event_transforms.functional.emulate_events` arguments:
    log-uniform ranges ``(low, high)`` become a geometric mean and a spread."""
    low, high = config.shot_noise_hz
    hot_low, hot_high = config.hot_pixel_hz
    return {
        "threshold_on": config.threshold, "mismatch": config.threshold_mismatch,
        "refractory_us": config.refractory_us, "noise_on_fraction": config.noise_on_fraction,
        "noise_hz": math.sqrt(low * high) if config.shot_noise else 0.0, "noise_spread": math.sqrt(high / low),
        "hot_pixel_fraction": config.hot_pixel_fraction if config.hot_pixels else 0.0,
        "hot_pixel_hz": math.sqrt(hot_low * hot_high), "hot_pixel_spread": math.sqrt(hot_high / hot_low),
        "leak_hz": optical.leak_hz, "random_reference": optical.random_reference,
    }


def _recording_seed(seed: int) -> int:
    """A grasp's emulation seed (63 bits) from its seed."""
    state = np.random.SeedSequence([seed, 0x0971C]).generate_state(2, np.uint32)
    return (int(state[0]) << 31) ^ int(state[1])
