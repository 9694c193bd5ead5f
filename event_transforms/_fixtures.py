"""Rig files in the formats the readers take (private), written for the tests and the reader
benchmark: ``.aedat4`` with trigger packets (faery's encoder; the aedat package only decodes)
and ROS 1/2 bags with events, a wrench topic and trigger pulses (rosbags' writer)."""

from __future__ import annotations

from pathlib import Path

import importlib
from typing import Any

import numpy as np


__all__ = ["write_aedat4", "write_bag"]


def _needs(package: str) -> Any:
    try:
        return importlib.import_module(package)
    except ImportError as error:
        raise ImportError(f"writing this rig file needs {package}: pip install {package}") from error


def write_aedat4(path: Path, events: np.ndarray, sensor: tuple[int, int], triggers: np.ndarray | None = None,
                 sources: int | np.ndarray = 1) -> None:
    """``events`` (fields x, y, t, p) and trigger times ``triggers`` (µs, source ``sources``) as an
    .aedat4 file stating ``sensor`` (H, W), through faery's AEDAT4 encoder (the aedat package
    only decodes)."""
    faery = _needs("faery")
    A = faery.aedat

    def attribute(kind: str, value: object) -> Any:
        return A.DescriptionAttribute(attribute_type=kind, value=value)

    def node(i: int, name: str, type_id: str, info: dict[str, int]) -> Any:
        return A.DescriptionNode(
            name=str(i), path=f"/mainloop/Recorder/outInfo/{i}/",
            attributes={"compression": attribute("string", "NONE"), "originalOutputName": attribute("string", name),
                        "typeIdentifier": attribute("string", type_id)},
            nodes=[A.DescriptionNode(name="info", path=f"/mainloop/Recorder/outInfo/{i}/info/",
                                     attributes={k: attribute("int", v) for k, v in info.items()}, nodes=[])])

    tracks = [node(0, "events", "EVTS", {"sizeX": sensor[1], "sizeY": sensor[0]})]
    if triggers is not None:
        tracks.append(node(1, "triggers", "TRIG", {}))
    description = [A.DescriptionNode(name="outInfo", path="/mainloop/Recorder/outInfo/", attributes={}, nodes=tracks)]
    packed = np.zeros(len(events), dtype=faery.EVENTS_DTYPE)
    packed["t"], packed["x"], packed["y"], packed["p"] = events["t"], events["x"], events["y"], events["p"] > 0
    with A.Encoder(str(path), description, None) as encoder:
        for part in np.array_split(packed, 3):
            encoder.write(0, part)
        if triggers is not None:
            trig = np.zeros(len(triggers), dtype=[("t", "<u8"), ("source", "u1")])
            trig["t"], trig["source"] = triggers, sources
            encoder.write(1, trig)


def write_bag(path: Path, events: np.ndarray, sensor: tuple[int, int], force_t_us: np.ndarray,
              wrench: np.ndarray, *, ros2: bool = False, per_message: int = 500, float_topic: bool = False,
              force_topic: str = "/ft", force_lag_us: int = 0, triggers_us: np.ndarray | None = None,
              events_type: str = "dvs_msgs/msg/EventArray") -> None:
    """A ROS 1 ``.bag`` (or a ROS 2 bag folder) with ``/dvs/events`` (dvs_msgs/EventArray, the
    custom types registered from their .msg text), ``/ft`` (geometry_msgs/WrenchStamped, ``wrench``
    rows fx, fy, fz stamped ``force_t_us - force_lag_us`` in the headers: the sensor's clock) and,
    with ``float_topic``, ``/grip`` (std_msgs/Float64, no header), and with ``triggers_us`` the same
    pulses as sensor_msgs/TimeReference on ``/dvs/trigger`` (camera clock) and ``/ft/trigger``
    (the force sensor's), written with rosbags' own writer. Event times are µs."""
    _needs("rosbags")
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    from event_transforms.events.bags import EVENT_MESSAGES

    store = get_typestore(Stores.ROS2_HUMBLE if ros2 else Stores.ROS1_NOETIC)
    types: dict = {}
    for array_type, (event_type, event_msg, array_msg) in EVENT_MESSAGES.items():
        types.update(get_types_from_msg(event_msg, event_type))
        types.update(get_types_from_msg(array_msg, array_type))
    store.register(types)
    T = store.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    Event = T[events_type.replace("EventArray", "Event")]
    Vector = T["geometry_msgs/msg/Vector3"]

    def stamp(t_us: int) -> Any:
        return Time(sec=int(t_us) // 1_000_000, nanosec=int(t_us) % 1_000_000 * 1000)

    def header(t_us: int, seq: int) -> Any:
        return Header(stamp=stamp(t_us), frame_id="sensor") if ros2 else Header(seq=seq, stamp=stamp(t_us),
                                                                                 frame_id="sensor")

    def serialize(message: Any, kind: str) -> bytes:
        return bytes(store.serialize_cdr(message, kind) if ros2 else store.serialize_ros1(message, kind))

    writer: Any
    if ros2:
        from rosbags.rosbag2 import Writer as Writer2

        writer = Writer2(path, version=8)
    else:
        from rosbags.rosbag1 import Writer as Writer1

        writer = Writer1(path)
    receive_shift = 3_000  # the bag receives each message 3 ms after its stamp
    with writer:
        on_events = writer.add_connection("/dvs/events", events_type, typestore=store)
        on_force = writer.add_connection(force_topic, "geometry_msgs/msg/WrenchStamped", typestore=store)
        on_grip = writer.add_connection("/grip", "std_msgs/msg/Float64", typestore=store) if float_topic else None
        messages = []
        for k, start in enumerate(range(0, len(events), per_message)):
            part = events[start:start + per_message]
            array = T[events_type](
                header=header(int(part["t"][-1]), k), height=sensor[0], width=sensor[1],
                events=[Event(x=int(e["x"]), y=int(e["y"]), ts=stamp(int(e["t"])), polarity=bool(e["p"] > 0))
                        for e in part])
            messages.append((int(part["t"][-1]) + receive_shift, on_events, serialize(array, events_type)))
        for k, (t, (fx, fy, fz)) in enumerate(zip(force_t_us, wrench)):
            wrench_msg = T["geometry_msgs/msg/WrenchStamped"](
                header=header(int(t) - force_lag_us, k), wrench=T["geometry_msgs/msg/Wrench"](
                    force=Vector(x=float(fx), y=float(fy), z=float(fz)), torque=Vector(x=0.0, y=0.0, z=0.0)))
            messages.append((int(t) + receive_shift, on_force, serialize(wrench_msg, "geometry_msgs/msg/WrenchStamped")))
            if on_grip is not None:
                messages.append((int(t) + receive_shift, on_grip,
                                 serialize(T["std_msgs/msg/Float64"](data=float(fz)), "std_msgs/msg/Float64")))
        if triggers_us is not None:
            kind = "sensor_msgs/msg/TimeReference"
            for topic, lag in (("/dvs/trigger", 0), ("/ft/trigger", force_lag_us)):
                connection = writer.add_connection(topic, kind, typestore=store)
                for k, t in enumerate(triggers_us):
                    message = T[kind](header=header(int(t) - lag, k), time_ref=stamp(int(t) - lag), source="sync")
                    messages.append((int(t) + receive_shift, connection, serialize(message, kind)))
        for t, connection, raw in sorted(messages, key=lambda m: m[0]):
            writer.write(connection, t * 1000, raw)
