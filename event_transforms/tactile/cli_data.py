"""The command line's ingestion options (one set for every command that reads recordings),
``convert`` (a ROS bag written in the recording-set layout) and the translation of the
library's advice (``sensor_size=(H, W)``) into the flags a command-line user types
(``--sensor-size H W``).
"""

from __future__ import annotations

__all__ = ["add_ingestion_options", "add_recording_options", "recording_settings", "as_flags", "add_convert_command",
           "run_convert"]

import argparse
import dataclasses
import math
import re
from pathlib import Path
from typing import Any

#: Python keyword -> command-line flag, for errors raised below the command line.
_FLAGS = {
    "sensor_size": "--sensor-size", "time_unit": "--time-unit", "columns": "--columns", "frames": "--frames",
    "frame_ms": "--frame-ms", "stride": "--stride", "force_offset_ms": "--force-offset-ms",
    "force_time_unit": "--force-time-unit", "force_column": "--force-column", "sync": "--sync", "crop": "--crop",
}
_ADVICE = re.compile(r"\b(" + "|".join(_FLAGS) + r")=(\((\w+), (\w+)\)|'([^']*)'|(-?[\d.]+))?")
_LEAVE = re.compile(r"\bleave (" + "|".join(_FLAGS) + r") out\b")


def as_flags(message: str) -> str:
    """An error message with the Python keywords it advises written as command-line flags.

    Args:
        message: the message raised by the library.

    Example:
        >>> as_flags("pass sensor_size=(240, 320); or time_unit='ms'; lower frames= (frames=36)")
        'pass --sensor-size 240 320; or --time-unit ms; lower --frames (--frames 36)'
        >>> as_flags("pass sensor_size=(H, W); or leave sensor_size out")
        'pass --sensor-size H W; or leave --sensor-size out'
    """

    def flag(match: re.Match[str]) -> str:
        name = _FLAGS[match.group(1)]
        if match.group(3) is not None:
            return f"{name} {match.group(3)} {match.group(4)}"
        value = match.group(5) if match.group(5) is not None else match.group(6)
        return name if value is None else f"{name} {value}"

    return _LEAVE.sub(lambda match: f"leave {_FLAGS[match.group(1)]} out", _ADVICE.sub(flag, message))


def _positive(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return value


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def _non_negative_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a non-negative integer, got {text!r}")
    return value


def _finite(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def add_ingestion_options(group: Any) -> None:
    """How event files are read, the options every command that reads one takes
    (``--sensor-size``, ``--time-unit``, ``--columns``).

    Args:
        group: an argparse parser or argument group.

    Example:
        >>> parser = argparse.ArgumentParser()
        >>> add_ingestion_options(parser)
        >>> parser.parse_args(["--sensor-size", "240", "320", "--columns", "txyp"]).sensor_size
        [240, 320]
    """
    group.add_argument("--sensor-size", type=_positive, nargs=2, metavar=("H", "W"), default=None,
                       help="sensor height and width (default: the size the event files state (.aedat4, HDF5), "
                       "else 180 240, the DAVIS240)")
    group.add_argument("--time-unit", choices=("us", "ms", "s", "ns"),
                       help="unit of the event files' timestamps (default: microseconds; float timestamps that "
                       "look like seconds and integers that look like milliseconds are refused without it)")
    group.add_argument("--columns", metavar="ORDER",
                       help="column order of (N, k) event arrays (.npy, plain HDF5), e.g. txyp ('_' skips a column; "
                       "default xytp)")


def add_recording_options(parser: argparse.ArgumentParser) -> None:
    """The layout's settings (:class:`~event_transforms.tactile.recordings.RecordingSettings`),
    each recorded with the results.

    Args:
        parser: the command's parser.

    Example:
        >>> parser = argparse.ArgumentParser()
        >>> add_recording_options(parser)
        >>> recording_settings(parser.parse_args(["--force-column", "magnitude"])).force_column
        'magnitude'
    """
    group = parser.add_argument_group("recordings (with --data)")
    add_ingestion_options(group)
    group.add_argument("--frame-ms", type=_positive_float, default=10.0, help="bin width in ms (default 10)")
    group.add_argument("--frames", type=_positive, default=36, help="frames T per window (default 36)")
    group.add_argument("--stride", type=_positive, help="frames between window starts (default T)")
    group.add_argument("--crop", type=_non_negative_int, nargs=4, metavar=("TOP", "LEFT", "H", "W"),
                       help="crop window for every recording (default: recordings.csv's crop columns, else the "
                       "contact area of the training recordings)")
    group.add_argument("--pool", type=_positive, default=2, help="sum-pool factor (default 2)")
    group.add_argument("--force-offset-ms", type=_finite, default=0.0,
                       help="the force clock's lag behind the events' clock in ms (default 0)")
    group.add_argument("--force-time-unit", choices=("us", "ms", "s", "ns"),
                       help="unit of a force time column whose name does not say it (t, time, timestamp; the "
                       "names t_ns, t_us, t_ms, t_s say it)")
    group.add_argument("--force-column", metavar="NAME",
                       help="the force CSV's label column (default force_n), e.g. fz, or 'magnitude': the norm of "
                       "fx, fy, fz")
    group.add_argument("--sync", choices=("triggers",),
                       help="align each recording's force clock to the camera's from the .aedat4 trigger events "
                       "and the force CSV's trigger column (instead of --force-offset-ms)")


def recording_settings(args: argparse.Namespace) -> Any:
    """The :class:`~event_transforms.tactile.recordings.RecordingSettings` the options give.

    Args:
        args: parsed options of :func:`add_recording_options`.

    Example:
        See :func:`add_recording_options`.
    """
    from .recordings import RecordingSettings

    return RecordingSettings(
        sensor_size=None if args.sensor_size is None else tuple(args.sensor_size), frame_ms=args.frame_ms,
        frames=args.frames, stride=args.stride, crop=None if args.crop is None else tuple(args.crop), pool=args.pool,
        force_offset_ms=args.force_offset_ms, time_unit=args.time_unit, columns=args.columns,
        force_time_unit=args.force_time_unit, force_column=args.force_column, sync=args.sync,
    )


#: Suffixes read as videos by ``convert`` (anything else is a ROS bag).
VIDEO_SUFFIXES = (".avi", ".mp4", ".mov", ".mkv", ".webm")


def _is_video_input(path: Path) -> bool:
    """A video file, or a folder of ``<day>/<name>.avi`` videos (a ROS 2 bag folder holds metadata.yaml)."""
    if path.suffix.lower() in VIDEO_SUFFIXES:
        return True
    return path.is_dir() and not (path / "metadata.yaml").is_file() and any(path.glob("*/*.avi"))


def _channel(value: str) -> str | int:
    if value in ("mean", "luma"):
        return value
    if value in ("0", "1", "2", "red", "green", "blue"):
        return {"red": 0, "green": 1, "blue": 2}.get(value, int(value) if value.isdigit() else 0)
    raise argparse.ArgumentTypeError(f"expected mean, luma, red, green, blue or 0, 1, 2, got {value!r}")


def add_convert_command(sub: Any) -> None:
    """``convert BAG... --events TOPIC [--force TOPIC] --out DIR`` (ROS bags) and
    ``convert VIDEO --force FILE.csv --out DIR`` / ``convert FOLDER --out DIR`` (videos, events emulated).

    Args:
        sub: the subparsers of the ``event-transforms`` parser.

    Example:
        >>> parser = argparse.ArgumentParser()
        >>> add_convert_command(parser.add_subparsers(dest="command"))
        >>> args = parser.parse_args(["convert", "a.bag", "--events", "/dvs/events", "--out", "rec"])
        >>> args.role, args.stamps
        ('train', 'header')
        >>> parser.parse_args(["convert", "grasp.avi", "--force", "f.csv", "--out", "rec", "--channel", "red"]).channel
        0
    """
    convert = sub.add_parser(
        "convert", help="write ROS bags or frame-camera videos in the recording-set layout",
        description="ROS bags: read the events (dvs_msgs/EventArray or prophesee_event_msgs/EventArray) and the force "
        "(geometry_msgs/WrenchStamped or any numeric field) of each bag and write them as one recording each of "
        "the layout in --out (events/<bag>.npz with the sensor size, force/<bag>.csv, a row of recordings.csv). "
        "Needs the bag extra: pip install 'event-transforms[bag]'. Videos (a tactile sensor's frame camera): the "
        "events are emulated (event_transforms.functional.emulate_events) on the gel's rectified crop, the force "
        "CSV (--force) is written on the frames' clock, and the emulator's settings go to emulator.json; a folder "
        "of <day>/<name>.avi with <name>_forces.pkl and <name>_widths.pkl (the GelSight Wedge grasps' layout) "
        "converts one recording per grasp. Needs the video extra: pip install 'event-transforms[video]'.")
    convert.add_argument("bags", type=Path, nargs="+", metavar="INPUT",
                         help="ROS 1 .bag files or ROS 2 bag folders; or a video; or a folder of <day>/<name>.avi")
    convert.add_argument("--events", metavar="TOPIC", help="bags: the events' topic, e.g. /dvs/events (required)")
    convert.add_argument("--force", metavar="TOPIC|FILE",
                         help="bags: the force topic; a video: a CSV with t_us (or t_s, t_ms, t_ns) and force_n "
                         "(default: none, unlabeled recordings)")
    convert.add_argument("--force-field", metavar="FIELD",
                         help="magnitude (a wrench's default), fx, fy, fz, or a dotted numeric field (data, "
                         "wrench.torque.z)")
    convert.add_argument("--stamps", choices=("header", "receive"), default="header",
                         help="force times: the messages' header stamps (default) or the bag's receive times")
    convert.add_argument("--triggers", nargs=2, metavar=("CAMERA_TOPIC", "FORCE_TOPIC"),
                         help="the same trigger pulses stamped on the camera's clock and on the force sensor's: the "
                         "force times are moved to the camera's clock by their median difference")
    convert.add_argument("--role", choices=("train", "deploy"), default="train", help="the rows' role (default train)")
    convert.add_argument("--diameter-mm", type=_positive_float, help="the object's size, for a diameter_mm column")
    convert.add_argument("--out", type=Path, required=True, metavar="DIR", help="the layout's folder")
    video = convert.add_argument_group("videos (events emulated; the settings are written to emulator.json)")
    video.add_argument("--channel", type=_channel, default=None,
                       help="RGB to one luminance: mean, luma (BT.601), red, green or blue (default green, chosen on "
                       "training grasps: docs/recordings.md)")
    video.add_argument("--threshold", type=_positive_float, default=None,
                       help="contrast threshold, log units (default 0.03, chosen likewise)")
    video.add_argument("--mismatch", type=float, default=None,
                       help="relative spread of the per-pixel thresholds (default 0.03)")
    video.add_argument("--refractory-us", type=float, default=None, help="refractory period, microseconds (default 0)")
    video.add_argument("--whole-frame", action="store_true",
                       help="emulate the whole frame instead of the GelSight Wedge gel's rectified quadrilateral")


def run_convert(args: argparse.Namespace, log: Any) -> int:
    """Run ``convert`` (each bag one row; every line of what was read is given to ``log``).

    Args:
        args: the parsed ``convert`` options.
        log: called with one line per bag.

    Example:
        See :func:`add_convert_command`.
    """
    videos = [_is_video_input(path) for path in args.bags]
    if any(videos):
        if not all(videos):
            raise ValueError("convert takes either ROS bags or videos in one call, not both")
        return _run_convert_videos(args, log)
    if args.events is None:
        raise ValueError("convert: a ROS bag needs --events TOPIC (the events' topic, e.g. /dvs/events)")
    from .recordings.convert import convert_bag

    for bag in args.bags:
        convert_bag(bag, args.out, events=args.events, force=args.force, force_field=args.force_field,
                    stamps=args.stamps, role=args.role, diameter_mm=args.diameter_mm,
                    triggers=None if args.triggers is None else tuple(args.triggers), log=log)
    return 0


def _run_convert_videos(args: argparse.Namespace, log: Any) -> int:
    """``convert`` on videos or a folder of them (see :func:`add_convert_command`)."""
    from .recordings.video import FORCE_RULE, VideoEmulation, convert_video, convert_video_folder

    for flag, value in (("--events", args.events), ("--triggers", args.triggers), ("--force-field", args.force_field)):
        if value is not None:
            raise ValueError(f"convert: {flag} is for ROS bags; a video's events are emulated")
    given = {"channel": args.channel, "threshold": args.threshold, "mismatch": args.mismatch,
             "refractory_us": args.refractory_us}
    settings = dataclasses.replace(VideoEmulation(), **{k: v for k, v in given.items() if v is not None})
    if args.whole_frame:
        settings = dataclasses.replace(settings, corners_xy=None)
    log(f"emulator: {settings.as_dict()}")
    for path in args.bags:
        if path.is_dir():
            if args.force is not None:
                raise ValueError(f"convert {path}: a folder of grasps reads its <name>_forces.pkl; leave --force out")
            convert_video_folder(path, args.out, settings=settings, role=args.role, log=log)
        else:
            convert_video(path, args.out, force=args.force, settings=settings, role=args.role, log=log)
            log(FORCE_RULE)
    return 0
