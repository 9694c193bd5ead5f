"""ROS 1 and ROS 2 bags read without ROS, through the ``rosbags`` package (the ``bag`` extra):
events from ``dvs_msgs/EventArray`` or Prophesee's ``EventArray`` (read as arrays where the
messages have the standard layout), one number per message (a wrench's force, any numeric
field) and message stamps (trigger pulses). Re-exported by :mod:`event_transforms.events.io`;
``event-transforms convert`` writes a bag in the recordings layout with them.
"""

from __future__ import annotations

__all__ = ["EVENT_MESSAGES", "read_bag_events", "read_bag_values", "read_bag_stamps"]

import os
from pathlib import Path
from typing import Any

import numpy as np

#: Event-array message types read from bags, with their ``.msg`` definitions (registered with
#: rosbags' type system where a bag does not carry them, as ROS 2 bags may not).
EVENT_MESSAGES = {
    "dvs_msgs/msg/EventArray": ("dvs_msgs/msg/Event", "uint16 x\nuint16 y\ntime ts\nbool polarity\n",
                                "std_msgs/Header header\nuint32 height\nuint32 width\ndvs_msgs/Event[] events\n"),
    "prophesee_event_msgs/msg/EventArray": (
        "prophesee_event_msgs/msg/Event", "uint16 x\nuint16 y\ntime ts\nbool polarity\n",
        "std_msgs/Header header\nuint32 height\nuint32 width\nprophesee_event_msgs/Event[] events\n"),
}
#: One event of a ROS 1 ``EventArray`` as serialised (packed: x, y, ts.sec, ts.nsec, polarity).
_ROS1_EVENT = np.dtype([("x", "<u2"), ("y", "<u2"), ("sec", "<u4"), ("nsec", "<u4"), ("p", "u1")])
#: The same in little-endian CDR (ROS 2), after the first event: each element is aligned, so
#: from the second on they repeat every 16 bytes (x, y, 2 bytes of padding, sec, nanosec, polarity).
_CDR_EVENT = np.dtype({"names": ["x", "y", "sec", "nsec", "p"], "formats": ["<u2", "<u2", "<i4", "<u4", "u1"],
                       "offsets": [0, 2, 6, 10, 14], "itemsize": 16})
_EVENT_COLUMNS = [("x", "<i4"), ("y", "<i4"), ("t", "<i8"), ("p", "<i1")]


def _ros1_events(raw: bytes) -> tuple[int, int, np.ndarray] | None:
    """(height, width, records) of a ROS 1 serialised EventArray (``None``: not that layout)."""
    at = 12 + 4 + int(np.frombuffer(raw, "<u4", 1, 12)[0])  # past seq, stamp and the frame_id
    height, width, count = (int(v) for v in np.frombuffer(raw, "<u4", 3, at))
    if len(raw) != at + 12 + count * _ROS1_EVENT.itemsize:  # another definition: deserialised instead
        return None
    return height, width, np.frombuffer(raw, _ROS1_EVENT, count, at + 12)


def _cdr_events(raw: bytes) -> tuple[int, int, np.ndarray] | None:
    """(height, width, records) of a little-endian CDR EventArray (``None``: another encoding)."""
    if raw[:2] != b"\x00\x01":
        return None
    body = memoryview(raw)[4:]
    at = 12 + int(np.frombuffer(body, "<u4", 1, 8)[0])  # past the stamp and the frame_id
    at += -at % 4
    height, width, count = (int(v) for v in np.frombuffer(body, "<u4", 3, at))
    at += 12
    if count and len(body) < at + (13 if count == 1 else 16 * count - 3):  # another definition: deserialised
        return None
    records = np.zeros(count, dtype=_ROS1_EVENT)
    if count:
        first = np.frombuffer(body, _ROS1_EVENT, 1, at)
        records[0] = first[0]
        # the last element has no trailing padding byte: one is added to read it as the others
        rest = np.frombuffer(bytes(body[at + 14:]) + b"\x00", _CDR_EVENT, count - 1) if count > 1 else None
        if rest is not None:
            for name in ("x", "y", "sec", "nsec", "p"):
                records[name][1:] = rest[name]
    return height, width, records


def _bag_reader(path: Path) -> Any:
    """An opened rosbags ``AnyReader`` on ``path`` (ROS 1 file or ROS 2 folder), the event
    message types registered."""
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    except ImportError:
        raise ValueError(f"{path}: reading ROS bags needs rosbags: pip install 'event-transforms[bag]'") from None
    if not path.exists():
        raise ValueError(f"bag {str(path)!r} does not exist")
    store = get_typestore(Stores.ROS2_HUMBLE if path.is_dir() else Stores.ROS1_NOETIC)
    types: dict[str, Any] = {}
    for array_type, (event_type, event_msg, array_msg) in EVENT_MESSAGES.items():
        types.update(get_types_from_msg(event_msg, event_type))
        types.update(get_types_from_msg(array_msg, array_type))
    store.register(types)
    reader = AnyReader([path], default_typestore=store)
    try:
        reader.open()
    except Exception as error:  # noqa: BLE001 - rosbags' own errors, named once
        raise ValueError(f"{path}: not a readable ROS bag ({type(error).__name__}: {error})") from None
    return reader


def _connections(reader: Any, path: Path, topic: str, option: str) -> list[Any]:
    found = [c for c in reader.connections if c.topic == topic]
    if not found:
        topics = sorted({f"{c.topic} ({c.msgtype})" for c in reader.connections})
        raise ValueError(f"{path}: no topic {topic!r} for the {option}; the bag holds "
                         f"{', '.join(topics) or 'no topic'}: name one of them")
    return found


def read_bag_events(path: str | os.PathLike[str], topic: str) -> tuple[dict[str, np.ndarray], tuple[int, int] | None]:
    """The events of one topic of a ROS 1 or ROS 2 bag (``dvs_msgs/EventArray`` or Prophesee's
    ``EventArray``), through the ``rosbags`` package (the ``bag`` extra).

    Args:
        path: the bag (a ROS 1 ``.bag`` file or a ROS 2 bag folder).
        topic: the events' topic, e.g. ``"/dvs/events"``.

    Returns:
        Columns ``x, y, t, p`` with ``t`` the events' own stamps (``ts``) in int64
        nanoseconds, and the sensor ``(H, W)`` the messages state (``None`` if they state 0).

    Shape:
        Four numpy columns of length N, in the order of the messages.

    Raises:
        ValueError: naming the bag and the topic: a missing topic (with the topics the bag
            holds), a message type that holds no events, sizes that change between messages.

    Example:
        >>> read_bag_events("missing.bag", "/dvs/events")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: ...
    """
    path = Path(path)
    reader = _bag_reader(path)
    parts: list[np.ndarray] = []
    sizes: set[tuple[int, int]] = set()
    try:
        connections = _connections(reader, path, topic, "events")
        for connection in connections:
            if connection.msgtype not in EVENT_MESSAGES:
                raise ValueError(f"{path}: topic {topic!r} carries {connection.msgtype}, not an event array "
                                 f"({', '.join(EVENT_MESSAGES)})")
        for connection, _, raw in reader.messages(connections=connections):
            packed = _cdr_events(raw) if reader.is2 else _ros1_events(raw)  # read as arrays, not objects
            if packed is not None:
                height, width, records = packed
                part = np.empty(len(records), dtype=_EVENT_COLUMNS)
                part["x"], part["y"], part["p"] = records["x"], records["y"], records["p"]
                part["t"] = records["sec"].astype(np.int64) * 1_000_000_000 + records["nsec"]
            else:
                message = reader.deserialize(raw, connection.msgtype)
                height, width = int(message.height), int(message.width)
                part = np.empty(len(message.events), dtype=[("x", "<i4"), ("y", "<i4"), ("t", "<i8"), ("p", "<i1")])
                part["x"] = [e.x for e in message.events]
                part["y"] = [e.y for e in message.events]
                part["t"] = [e.ts.sec * 1_000_000_000 + e.ts.nanosec for e in message.events]
                part["p"] = [e.polarity for e in message.events]
            sizes.add((height, width))
            parts.append(part)
    finally:
        reader.close()
    sizes.discard((0, 0))
    if len(sizes) > 1:
        raise ValueError(f"{path}: topic {topic!r} states sensor sizes {sorted(sizes)} in different messages")
    events = np.concatenate(parts) if parts else np.zeros(0, dtype=[("x", "<i4"), ("y", "<i4"), ("t", "<i8"),
                                                                      ("p", "<i1")])
    return {c: events[c] for c in "xytp"}, (sizes.pop() if sizes else None)


def _field(message: Any, name: str) -> float:
    value = message
    for part in name.split("."):
        value = getattr(value, part)
    return float(value)


def _open_topic(path: str | os.PathLike[str], topic: str, option: str, stamps: str) -> tuple[Path, Any, list[Any]]:
    """The bag's reader and ``topic``'s connections, ``stamps`` checked (the reader is closed
    again when the topic is missing)."""
    if stamps not in ("header", "receive"):
        raise ValueError(f"stamps must be 'header' or 'receive', got {stamps!r}")
    path = Path(path)
    reader = _bag_reader(path)
    try:
        return path, reader, _connections(reader, path, topic, option)
    except BaseException:
        reader.close()
        raise


def _stamp(where: str, msgtype: str, message: Any, received: int, stamps: str) -> int:
    """A message's time in nanoseconds: its ``header.stamp``, or the time the bag received it.

    Raises:
        ValueError: with ``stamps="header"``, a message without a header or stamped 0, named by ``where``.
    """
    if stamps == "receive":
        return int(received)
    header = getattr(message, "header", None)
    if header is None:
        raise ValueError(f"{where} ({msgtype}) has no header to stamp it; pass --stamps receive to use the time "
                         "the bag recorded it")
    stamp = int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
    if stamp == 0:
        raise ValueError(f"{where}: the header stamp is 0 (the publisher did not stamp it); pass --stamps receive "
                         "to use the time the bag recorded it")
    return stamp


def read_bag_values(
    path: str | os.PathLike[str], topic: str, *, field: str | None = None, stamps: str = "header",
) -> tuple[np.ndarray, np.ndarray, str]:
    """One number per message of a bag's topic, with its time: a force from
    ``geometry_msgs/WrenchStamped`` or any numeric field.

    Args:
        path: the bag (ROS 1 file or ROS 2 folder).
        topic: the topic, e.g. ``"/ft_sensor/wrench"``.
        field: ``"magnitude"`` (default for a wrench: the norm of ``wrench.force``), an axis
            ``"fx"``/``"fy"``/``"fz"`` of a wrench, or a dotted path to a numeric field of the
            message (``"data"``, ``"wrench.torque.z"``).
        stamps: ``"header"``: each message's ``header.stamp`` (default); ``"receive"``: the
            time the bag recorded it.

    Returns:
        Times (int64 nanoseconds), values (float64) and a line saying what was read.

    Raises:
        ValueError: naming the bag, the topic and the message: a missing topic, a message
            without a header (or stamped 0) with ``stamps="header"``, a field that is not
            there or not a number, NaN.

    Example:
        >>> read_bag_values("missing.bag", "/wrench")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: ...
    """
    path, reader, connections = _open_topic(path, topic, "force", stamps)
    times: list[int] = []
    values: list[float] = []
    try:
        msgtype = connections[0].msgtype
        wrench = msgtype.endswith("WrenchStamped") or msgtype.endswith("/Wrench")
        chosen = field or ("magnitude" if wrench else None)
        if chosen is None:
            raise ValueError(f"{path}: topic {topic!r} carries {msgtype}: name the number to read with "
                             "--force-field (a dotted field, e.g. data)")
        prefix = "wrench." if msgtype.endswith("WrenchStamped") else ""
        axes = {"fx": "force.x", "fy": "force.y", "fz": "force.z"}
        for k, (connection, received, raw) in enumerate(reader.messages(connections=connections)):
            message = reader.deserialize(raw, connection.msgtype)
            where = f"{path}: topic {topic!r}, message {k}"
            try:
                if wrench and chosen == "magnitude":
                    force = _field(message, prefix + "force.x"), _field(message, prefix + "force.y"), \
                        _field(message, prefix + "force.z")
                    value = float(np.sqrt(np.square(force).sum()))
                else:
                    value = _field(message, prefix + axes[chosen] if wrench and chosen in axes else chosen)
            except AttributeError:
                raise ValueError(f"{where} ({msgtype}) has no field {chosen!r}; pass --force-field with one of its "
                                 "numeric fields") from None
            except (TypeError, ValueError):
                raise ValueError(f"{where}: field {chosen!r} is not a number") from None
            if not np.isfinite(value):
                raise ValueError(f"{where}: {chosen} is {value} (NaN or infinite); drop or filter the message "
                                 "before converting")
            times.append(_stamp(where, msgtype, message, received, stamps))
            values.append(value)
    finally:
        reader.close()
    said = f"{chosen} of {msgtype}" if wrench else f"field {chosen} of {msgtype}"
    what = f"{len(values)} values from {topic} ({said}, {'header stamps' if stamps == 'header' else 'receive times'})"
    return np.asarray(times, dtype=np.int64), np.asarray(values, dtype=np.float64), what


def read_bag_stamps(path: str | os.PathLike[str], topic: str, *, stamps: str = "header") -> np.ndarray:
    """The times (int64 nanoseconds) of a topic's messages: trigger pulses as a driver or a
    logger publishes them (any message type).

    Args:
        path: the bag (ROS 1 file or ROS 2 folder).
        topic: the trigger topic.
        stamps: ``"header"`` (each message's ``header.stamp``) or ``"receive"``.

    Raises:
        ValueError: naming the bag, the topic and the message: a missing topic, a message
            without a header (or stamped 0) with ``stamps="header"``.

    Example:
        >>> read_bag_stamps("missing.bag", "/trigger")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: ...
    """
    path, reader, connections = _open_topic(path, topic, "triggers", stamps)
    times: list[int] = []
    try:
        for k, (connection, received, raw) in enumerate(reader.messages(connections=connections)):
            message = None if stamps == "receive" else reader.deserialize(raw, connection.msgtype)
            times.append(_stamp(f"{path}: topic {topic!r}, message {k}", connection.msgtype, message, received,
                                stamps))
    finally:
        reader.close()
    return np.asarray(times, dtype=np.int64)
