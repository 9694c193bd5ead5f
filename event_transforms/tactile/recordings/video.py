"""Frame-camera tactile videos in the recording-set layout (``event-transforms convert VIDEO``).

A vision-based tactile sensor (GelSight, DIGIT, GelSight Mini) is a frame camera. A video
becomes a recording of the layout by emulating a DVS on it
(:func:`event_transforms.functional.emulate_events`, the library's one pixel model): the
gel's quadrilateral is rectified to a rectangle (a homography, bilinear), the colour
channels become one luminance by a stated rule, and the emulator's settings are written
beside the recordings (``emulator.json``) so that every result can cite them. The frames'
times are the video's presentation times from the first frame, the events' clock; a force CSV
is on that clock, and a per-frame force (the pickled labels) is written at its frame's time. Between two frames the emulator interpolates the log
intensity linearly: timing finer than a frame (33 ms at 30 frames/s) is an interpolation.

Videos are decoded with PyAV (the ``video`` extra), ``chunk_frames`` frames at a time: the
decoded RGB frames are never all in memory, only the rectified luminance of one video
(``4 · H · W`` bytes a frame: 0.6 MB for the 370 × 400 gel crop).

A folder in the layout of the GelSight Wedge grasps (``<day>/<name>.avi`` with
``<name>_forces.pkl`` and ``<name>_widths.pkl``) converts with the same command, one
recording per grasp, with ``object``, ``session`` (the day) and ``trial`` columns and the
gripper width as metadata (``width/<name>.csv``). Its pickles are read by
:func:`read_array_pickle`, which admits exactly the numpy globals of a pickled array and
refuses any other global by name: ``pickle.load`` is never called.
"""

from __future__ import annotations

__all__ = [
    "GEL_CORNERS_XY", "GEL_SIZE", "VideoEmulation", "read_array_pickle", "iter_video", "rectify_gel",
    "video_luminance", "convert_video", "convert_video_folder", "FORCE_RULE",
]

import csv
import dataclasses
import importlib
import json
import os
import pickle
import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # torch is imported where it is used: the command line's help loads no torch
    from torch import Tensor

from .._files import atomic_write, write_json_atomic
from .labels import read_force

#: The GelSight Wedge's gel in its 640 × 480 frame, (x, y) pixel corners top-left, top-right,
#: bottom-right, bottom-left (the source repository's ``wedge_config/config.csv``).
GEL_CORNERS_XY = ((67.0, 68.0), (465.0, 113.0), (475.0, 383.0), (73.0, 437.0))
#: The rectified gel's (H, W): about the quadrilateral's left edge and top edge.
GEL_SIZE = (370, 400)
#: What the converter does with negative force readings (a grip cannot pull): printed per run.
FORCE_RULE = "force readings below 0 N are clipped to 0 N (counted per grasp in the force_clipped column)"

_ALLOWED_GLOBALS = {
    ("numpy.core.multiarray", "_reconstruct"), ("numpy._core.multiarray", "_reconstruct"),
    ("numpy", "ndarray"), ("numpy", "dtype"),
}


class _ArrayUnpickler(pickle.Unpickler):
    """Admits the three globals of a pickled numpy array, refuses every other one by name."""

    def find_class(self, module: str, name: str) -> Any:
        if (module, name) not in _ALLOWED_GLOBALS:
            raise pickle.UnpicklingError(
                f"refused global {module}.{name}: only numpy.core.multiarray._reconstruct, numpy.ndarray and "
                "numpy.dtype are admitted in a label pickle")
        if name == "_reconstruct":  # numpy 2 keeps it in numpy._core; numpy 1 in numpy.core
            for where in ("numpy._core.multiarray", "numpy.core.multiarray"):
                try:
                    return getattr(importlib.import_module(where), "_reconstruct")
                except (ImportError, AttributeError):
                    continue
        return getattr(importlib.import_module("numpy"), name)


def read_array_pickle(path: str | os.PathLike[str]) -> np.ndarray:
    """A 1-D float64 array from a pickle of one ``numpy.ndarray``, by a restricted unpickler.

    Only ``numpy.core.multiarray._reconstruct`` (``numpy._core.multiarray._reconstruct`` in
    numpy 2), ``numpy.ndarray`` and ``numpy.dtype`` may be named by the pickle; any other
    global is refused by name before anything is called, so a malicious file runs nothing.

    Args:
        path: the ``.pkl`` file.

    Raises:
        ValueError: the file names another global, or holds something other than a 1-D
            numeric array (the message names the file).

    Example:
        >>> import tempfile
        >>> path = Path(tempfile.mkdtemp()) / "f.pkl"
        >>> path.write_bytes(pickle.dumps(np.array([1.5, 2.0])))  # doctest: +ELLIPSIS
        1...
        >>> read_array_pickle(path).tolist()
        [1.5, 2.0]
    """
    path = Path(path)
    with open(path, "rb") as handle:
        try:
            value = _ArrayUnpickler(handle).load()
        except pickle.UnpicklingError as error:
            raise ValueError(f"{path}: {error}") from None
    if not isinstance(value, np.ndarray) or value.ndim != 1 or not np.issubdtype(value.dtype, np.number):
        shown = f"array of shape {value.shape} and dtype {value.dtype}" if isinstance(value, np.ndarray) else type(value).__name__
        raise ValueError(f"{path}: expected a 1-D numeric array, got {shown}")
    return value.astype(np.float64)


def iter_video(path: str | os.PathLike[str], chunk_frames: int = 32) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Decode a video ``chunk_frames`` frames at a time with PyAV (the ``video`` extra).

    Args:
        path: the video file (any format FFmpeg reads).
        chunk_frames: frames per chunk.

    Yields:
        ``(frames, t_us)``: uint8 RGB ``(n, H, W, 3)`` and the frames' presentation times in
        microseconds (float64), on the video's clock.

    Example:
        >>> import tempfile
        >>> path = Path(tempfile.mkdtemp()) / "v.avi"
        >>> _write_test_video(path, np.full((3, 8, 8, 3), 100, np.uint8))
        >>> [(frames.shape, times.round().tolist()) for frames, times in iter_video(path, chunk_frames=2)]
        [((2, 8, 8, 3), [0.0, 33333.0]), ((1, 8, 8, 3), [66667.0])]
    """
    try:
        import av
    except ImportError:  # pragma: no cover - the extra is installed in the test environment
        raise ImportError("reading videos needs PyAV: pip install 'event-transforms[video]'") from None
    frames: list[np.ndarray] = []
    times: list[float] = []
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        for index, frame in enumerate(container.decode(stream)):
            if frame.pts is not None and frame.time_base is not None:
                times.append(float(frame.pts * frame.time_base) * 1e6)
            else:
                times.append(index * 1e6 / float(stream.average_rate))
            frames.append(frame.to_ndarray(format="rgb24"))
            if len(frames) == chunk_frames:
                yield np.stack(frames), np.asarray(times)
                frames, times = [], []
    if frames:
        yield np.stack(frames), np.asarray(times)


def _write_test_video(path: Path, frames: np.ndarray, fps: int = 30) -> None:
    """Write uint8 RGB frames (T, H, W, 3) as an MJPG .avi with PyAV (for tests and examples)."""
    import av

    with av.open(str(path), "w") as container:
        stream = container.add_stream("mjpeg", rate=fps)
        stream.height, stream.width = frames.shape[1:3]
        stream.pix_fmt = "yuvj420p"
        for image in frames:
            for packet in stream.encode(av.VideoFrame.from_ndarray(np.ascontiguousarray(image), format="rgb24")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)


def _homography(corners_xy: Sequence[Sequence[float]], size: tuple[int, int]) -> np.ndarray:
    """3×3 map from output pixel (u, v, 1) to source pixel (x, y, w): output corners to ``corners_xy``."""
    height, width = size
    target = np.asarray(corners_xy, dtype=np.float64)
    out = np.array([[0, 0], [width - 1, 0], [width - 1, height - 1], [0, height - 1]], dtype=np.float64)
    rows = []
    for (u, v), (x, y) in zip(out, target):
        rows.append([u, v, 1, 0, 0, 0, -u * x, -v * x])
        rows.append([0, 0, 0, u, v, 1, -u * y, -v * y])
    solution = np.linalg.solve(np.asarray(rows), target.reshape(-1))
    return np.append(solution, 1.0).reshape(3, 3)


def rectify_gel(frames: Tensor, corners_xy: Sequence[Sequence[float]] = GEL_CORNERS_XY,
                size: tuple[int, int] = GEL_SIZE) -> Tensor:
    """Rectify a quadrilateral of each frame to an ``(H, W)`` rectangle (homography, bilinear).

    Args:
        frames: ``(N, C, H_in, W_in)`` float frames.
        corners_xy: the quadrilateral's (x, y) corners: top-left, top-right, bottom-right,
            bottom-left (pixel centres).
        size: the output's ``(H, W)``.

    Shape:
        - frames: ``(N, C, H_in, W_in)``; output: ``(N, C, H, W)``, same dtype.

    Example:
        >>> import torch
        >>> frames = torch.arange(20.0).view(1, 1, 4, 5)
        >>> rectify_gel(frames, ((1, 1), (3, 1), (3, 2), (1, 2)), (2, 3))[0, 0].round(decimals=4).tolist()
        [[6.0, 7.0, 8.0], [11.0, 12.0, 13.0]]
    """
    import torch

    height, width = size
    _, _, source_h, source_w = frames.shape
    homography = torch.from_numpy(_homography(corners_xy, size)).to(frames.device, torch.float64)
    v, u = torch.meshgrid(torch.arange(height, dtype=torch.float64, device=frames.device),
                          torch.arange(width, dtype=torch.float64, device=frames.device), indexing="ij")
    points = torch.stack([u, v, torch.ones_like(u)], -1) @ homography.T
    x, y = points[..., 0] / points[..., 2], points[..., 1] / points[..., 2]
    grid = torch.stack([2 * x / (source_w - 1) - 1, 2 * y / (source_h - 1) - 1], -1).to(frames.dtype)
    return torch.nn.functional.grid_sample(frames, grid.expand(frames.shape[0], -1, -1, -1), mode="bilinear",
                                           padding_mode="border", align_corners=True)


@dataclass(frozen=True)
class VideoEmulation:
    """The emulator's settings for a video (written to ``emulator.json`` beside the recordings).

    The defaults (green channel, threshold 0.03, the gel rectified) were chosen by
    ``benchmarks/tactile/video_settings.py`` on training grasps only (see ``docs/recordings.md``).

    Attributes:
        channel: how RGB becomes one luminance: ``"mean"``, ``"luma"`` or 0, 1, 2 (R, G, B).
        threshold: ON and OFF contrast threshold (log units).
        mismatch: relative spread of the per-pixel thresholds.
        refractory_us: refractory period, microseconds.
        noise_hz: emulated shot noise per pixel (0: the recording's own noise only).
        corners_xy: the gel's quadrilateral ((x, y) corners TL, TR, BR, BL), or ``None``: the whole frame.
        size: the rectified gel's ``(H, W)`` (unused without ``corners_xy``: the frame's own size).
        camera_seed: the emulated camera's seed (one camera for every recording).
        chunk_frames: frames decoded at a time.

    Example:
        >>> VideoEmulation(threshold=0.3).as_dict()["threshold"]
        0.3
    """

    channel: str | int = 1
    threshold: float = 0.03
    mismatch: float = 0.03
    refractory_us: float = 0.0
    noise_hz: float = 0.0
    corners_xy: tuple[tuple[float, float], ...] | None = GEL_CORNERS_XY
    size: tuple[int, int] = GEL_SIZE
    camera_seed: int = 0
    chunk_frames: int = 32

    def as_dict(self) -> dict[str, Any]:
        out = dataclasses.asdict(self)
        out["corners_xy"] = None if self.corners_xy is None else [list(c) for c in self.corners_xy]
        out["size"] = list(self.size)
        out["model"] = ("event_transforms.functional.emulate_events: lin-log (knee 20 DN), log intensity "
                        "interpolated linearly between frames (sub-frame timing is an interpolation)")
        return out


def _channel_weights(channel: str | int) -> Tensor:
    """The weights of R, G, B (scaled by 1/255) of ``channel`` (the rules of ``functional.to_luminance``)."""
    import torch

    from ...functional.emulate import to_luminance

    return to_luminance(torch.eye(3).view(3, 3, 1, 1), channel).view(3) / 255.0


def video_luminance(path: str | os.PathLike[str], settings: VideoEmulation) -> tuple[Tensor, np.ndarray]:
    """The video's rectified gel as luminance ``(T, H, W)`` float32 in [0, 1] and its frame times (µs).

    Decoded ``settings.chunk_frames`` at a time; only the luminance is kept.

    Args:
        path: the video.
        settings: crop, size and channel.

    Shape:
        - output: ``(T, H, W)`` float32 luminance and ``(T,)`` times.

    Example:
        >>> path = Path(__import__("tempfile").mkdtemp()) / "v.avi"
        >>> _write_test_video(path, np.full((2, 16, 16, 3), 128, np.uint8))
        >>> luminance, times = video_luminance(path, VideoEmulation(corners_xy=None, size=(16, 16)))
        >>> luminance.shape, round(float(luminance.mean()), 1)
        (torch.Size([2, 16, 16]), 0.5)
    """
    import torch

    weights = _channel_weights(settings.channel)
    parts, times = [], []
    for frames, t_us in iter_video(path, settings.chunk_frames):
        corners = settings.corners_xy
        if corners is not None:  # only the quadrilateral's bounding box is converted
            left, top = (max(0, int(min(c[k] for c in corners)) - 1) for k in (0, 1))
            right, bottom = (int(max(c[k] for c in corners)) + 2 for k in (0, 1))
            frames = frames[:, top:bottom, left:right]
            corners = tuple((x - left, y - top) for x, y in corners)
        luminance = (torch.from_numpy(frames).to(torch.float32) @ weights).unsqueeze(1)  # linear, so before the warp
        if corners is not None:
            luminance = rectify_gel(luminance, corners, settings.size)
        parts.append(luminance[:, 0])
        times.append(t_us)
    if not parts:
        raise ValueError(f"{path}: the video holds no frame")
    return torch.cat(parts), np.concatenate(times)


def _emulate(luminance: Tensor, times: np.ndarray, settings: VideoEmulation, seed: int) -> np.ndarray:
    import torch

    from ...functional.emulate import emulate_events

    events = emulate_events(
        luminance, frame_times_us=torch.from_numpy(times - times[0]), threshold_on=settings.threshold,
        mismatch=settings.mismatch, refractory_us=settings.refractory_us, noise_hz=settings.noise_hz,
        seed=seed, camera_seed=settings.camera_seed, chunk_frames=settings.chunk_frames,
    )
    out = np.empty(events.num_events, dtype=[("x", "<i2"), ("y", "<i2"), ("t", "<i8"), ("p", "i1")])
    for column in ("x", "y", "t", "p"):
        out[column] = getattr(events, column).numpy()
    return out


def _seed_of(name: str) -> int:
    """A recording's emulation seed from its name (stable across runs and machines)."""
    import hashlib

    return int.from_bytes(hashlib.sha256(name.encode()).digest()[:8], "little") >> 1


def _append_rows(out: Path, rows: list[dict[str, str]]) -> None:
    table = out / "recordings.csv"
    header = ["events", "force", "role", "object", "session", "trial", "width", "force_clipped", "force_min_n"]
    existing: list[dict[str, str]] = []
    if table.is_file():  # a table written before (by convert, by hand): its columns are kept
        with open(table, newline="") as handle:
            reader = csv.DictReader(handle)
            existing = list(reader)
            header = [*(reader.fieldnames or []), *(h for h in header if h not in (reader.fieldnames or []))]
        names = {row["events"] for row in existing}
        clash = [row["events"] for row in rows if row["events"] in names]
        if clash:
            raise ValueError(f"{table}: {clash[0]} is already a row; remove it to convert it again")
    with atomic_write(table, "w") as handle:
        writer = csv.DictWriter(handle, fieldnames=header, lineterminator="\n", extrasaction="ignore", restval="")
        writer.writeheader()
        writer.writerows([*existing, *rows])


def _write_recording(out: Path, name: str, luminance: Tensor, times: np.ndarray,
                     force: tuple[np.ndarray, np.ndarray] | None, settings: VideoEmulation,
                     width: np.ndarray | None = None, role: str = "train") -> dict[str, str]:
    """Emulate and write one recording: events, force ``(t_us, force_n)`` samples on the events'
    clock (negative readings clipped to 0 N, counted), and the width per frame if given."""
    events = _emulate(luminance, times, settings, _seed_of(name))
    (out / "events").mkdir(parents=True, exist_ok=True)
    np.savez(out / "events" / f"{name}.npz", x=events["x"], y=events["y"], t=events["t"], p=events["p"],
             sensor_size=np.asarray(settings.size if settings.corners_xy is not None else luminance.shape[1:]))
    row = {"events": f"events/{name}.npz", "force": "", "role": role, "force_clipped": "", "force_min_n": ""}
    if force is not None:
        t_us, values = force
        clipped = int((values < 0).sum())
        (out / "force").mkdir(parents=True, exist_ok=True)
        with atomic_write(out / "force" / f"{name}.csv") as handle:
            handle.write("t_us,force_n\n")
            handle.writelines(f"{t:.1f},{v!r}\n" for t, v in zip(t_us.tolist(), np.maximum(values, 0.0).tolist()))
        row.update(force=f"force/{name}.csv", force_clipped=str(clipped), force_min_n=f"{values.min():.3f}")
    if width is not None:
        (out / "width").mkdir(parents=True, exist_ok=True)
        with atomic_write(out / "width" / f"{name}.csv") as handle:
            handle.write("t_us,width_m\n")
            handle.writelines(f"{t:.1f},{v!r}\n" for t, v in zip((times - times[0]).tolist(), width.tolist()))
        row["width"] = f"width/{name}.csv"
    row["_events"] = str(events.shape[0])
    return row


def _check_role(role: str) -> None:
    if role not in ("train", "deploy"):
        raise ValueError(f"role must be 'train' or 'deploy', got {role!r}")


def _write_settings(out: Path, settings: VideoEmulation, source: str) -> None:
    out.mkdir(parents=True, exist_ok=True)
    path = out / "emulator.json"
    record = {"settings": settings.as_dict(), "source": source, "force_rule": FORCE_RULE}
    if path.is_file():
        previous = json.loads(path.read_text())
        if previous.get("settings") != record["settings"]:
            raise ValueError(f"{path} records other emulator settings; convert into another folder")
        return
    write_json_atomic(path, record)


def convert_video(video: str | os.PathLike[str], out: str | os.PathLike[str], *, force: str | os.PathLike[str] | None,
                  settings: VideoEmulation | None = None, role: str = "train", log: Any = None) -> dict[str, str]:
    """Convert one video (and its force CSV, on the video's clock from its first frame) into a recording.

    Args:
        video: the video file.
        out: the layout's folder (``recordings.csv``, ``events/``, ``force/``, ``emulator.json``).
        force: a force CSV as the layout reads it (:func:`~event_transforms.tactile.recordings.read_force`:
            ``t_us``, ``t_ns``, ``t_ms`` or ``t_s`` and ``force_n``), on the video's clock (0 at the
            first frame), written at its own rate in microseconds (negative readings clipped to
            0 N and counted); ``None``: unlabeled.
        settings: the emulator's settings (default :class:`VideoEmulation`).
        role: the row's role, ``"train"`` or ``"deploy"``.
        log: called with one line of what was read and written.

    Returns:
        The row written to ``recordings.csv``.

    Example:
        >>> folder = Path(__import__("tempfile").mkdtemp())
        >>> frames = np.full((4, 16, 16, 3), 60, np.uint8); frames[2:, 4:12, 4:12] = 200
        >>> _write_test_video(folder / "press.avi", frames)
        >>> _ = (folder / "press.csv").write_text("t_us,force_n\\n0,0\\n100000,5\\n")
        >>> row = convert_video(folder / "press.avi", folder / "rec", force=folder / "press.csv",
        ...                     settings=VideoEmulation(corners_xy=None, size=(16, 16)))
        >>> row["events"], sorted(p.name for p in (folder / "rec").iterdir())
        ('events/press.npz', ['emulator.json', 'events', 'force', 'recordings.csv'])
    """
    settings = settings or VideoEmulation()
    _check_role(role)
    video, out = Path(video), Path(out)
    luminance, times = video_luminance(video, settings)
    labels = None if force is None else read_force(force, log=log)  # the layout's own reader and checks
    _write_settings(out, settings, str(video))
    row = _write_recording(out, video.stem, luminance, times, labels, settings, role=role)
    count = row.pop("_events")
    _append_rows(out, [row])
    if log:
        log(f"{video}: {times.size} frames -> {count} events, {row['events']}"
            + (f", {row['force']} ({row['force_clipped']} readings below 0 N clipped)" if labels is not None else ""))
    return row


_TRIAL = re.compile(r"^(?P<object>.+?)(?:__t=(?P<t>\d+)|_(?P<n>\d+))$")


def convert_video_folder(root: str | os.PathLike[str], out: str | os.PathLike[str], *,
                         settings: VideoEmulation | None = None, role: str = "train",
                         log: Any = None) -> list[dict[str, str]]:
    """Convert a folder of ``<day>/<name>.avi`` with ``<name>_forces.pkl`` and ``<name>_widths.pkl``.

    One recording per video (named ``<day>_<name>``), with ``object``, ``session`` (the
    day) and ``trial`` columns (from ``<object>__t=<k>`` or ``<object>_<k>``) and the
    gripper width written beside as ``width/<recording>.csv`` (metadata). The labels are
    read by :func:`read_array_pickle`. Negative force readings follow :data:`FORCE_RULE`;
    the count and the grasps with readings below -1 N are printed. The natural splits of the
    grasps the folder holds are written as scenes, ``out/scenes/<name>/recordings.csv``
    (:func:`~event_transforms.tactile.recordings.wedge_scenes.write_wedge_scenes`).

    Args:
        root: the folder.
        out: the layout's folder.
        settings: the emulator's settings (default :class:`VideoEmulation`).
        role: every row's role (the scenes of a folder assign their own splits).
        log: called with one line per grasp and a summary.

    Returns:
        The rows written.

    Example:
        >>> folder = Path(__import__("tempfile").mkdtemp())
        >>> (folder / "day1").mkdir()
        >>> _write_test_video(folder / "day1" / "ball__t=0.avi", np.full((3, 16, 16, 3), 90, np.uint8))
        >>> _ = (folder / "day1" / "ball__t=0_forces.pkl").write_bytes(pickle.dumps(np.array([0.0, -2.0, 3.0])))
        >>> _ = (folder / "day1" / "ball__t=0_widths.pkl").write_bytes(pickle.dumps(np.array([0.05, 0.04, 0.03])))
        >>> rows = convert_video_folder(folder, folder / "rec", settings=VideoEmulation(corners_xy=None, size=(16, 16)))
        >>> [(r["object"], r["session"], r["trial"], r["force_clipped"]) for r in rows]
        [('ball', 'day1', '0', '1')]
    """
    settings = settings or VideoEmulation()
    _check_role(role)
    root, out = Path(root), Path(out)
    videos = sorted(root.glob("*/*.avi"))
    if not videos:
        raise ValueError(f"{root}: no <day>/<name>.avi video")
    _write_settings(out, settings, str(root))
    rows, glitches, clipped = [], [], 0
    for video in videos:
        day, name = video.parent.name, video.stem
        forces = read_array_pickle(video.with_name(f"{name}_forces.pkl"))
        widths_path = video.with_name(f"{name}_widths.pkl")
        widths = read_array_pickle(widths_path) if widths_path.is_file() else None
        luminance, times = video_luminance(video, settings)
        if widths is not None and widths.shape[0] != times.shape[0]:
            raise ValueError(f"{widths_path}: {widths.shape[0]} widths for {times.shape[0]} video frames")
        match = _TRIAL.match(name)
        if forces.shape[0] != times.shape[0]:
            raise ValueError(f"{video}: {forces.shape[0]} force readings for {times.shape[0]} video frames")
        row = _write_recording(out, f"{day}_{name}", luminance, times, (times - times[0], forces), settings, widths,
                               role)
        row.update(object=match.group("object") if match else name, session=day,
                   trial=(match.group("t") or match.group("n")) if match else "")
        clipped += int(row["force_clipped"])
        if forces.min() < -1.0:
            glitches.append(f"{day}/{name} (min {forces.min():.1f} N)")
        count = row.pop("_events")
        if log:
            log(f"{video.relative_to(root)}: {times.size} frames -> {count} events")
        rows.append(row)
    _append_rows(out, rows)
    if log:
        log(f"{len(rows)} grasps -> {out / 'recordings.csv'}; {FORCE_RULE}: {clipped} readings in all; "
            f"readings below -1 N in {len(glitches)} grasps: {', '.join(glitches) if glitches else 'none'}")
    from .wedge_scenes import write_wedge_scenes

    if write_wedge_scenes(out, log=log) and log:
        log(f"each scene runs with: event-transforms reproduce --data {out / 'scenes' / '<scene>'} (see docs/recordings.md)")
    return rows
