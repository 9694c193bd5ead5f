"""ROS bags written in the recording-set layout (``event-transforms convert``): one reader
path for every command, whatever the rig recorded."""

from __future__ import annotations

__all__ = ["convert_bag"]

import csv
import os
from pathlib import Path
from typing import Any

import numpy as np

from ...events.bags import read_bag_events, read_bag_stamps, read_bag_values
from .._files import atomic_write


def convert_bag(
    bag: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    events: str,
    force: str | None = None,
    force_field: str | None = None,
    stamps: str = "header",
    role: str = "train",
    diameter_mm: float | None = None,
    triggers: tuple[str, str] | None = None,
    log: Any = None,
) -> int:
    """Write one bag's events and force as a recording of the layout in ``out`` and add its
    row to ``out/recordings.csv`` (created with the header ``events,force,role`` where missing).

    The events go to ``events/<bag>.npz`` (``x, y, t, p`` with ``t`` in integer microseconds,
    and ``sensor_size`` where the messages state it, so that the sensor size is read from the
    file); the force to ``force/<bag>.csv`` (``t_us,force_n``, on the same clock).

    Args:
        bag: a ROS 1 ``.bag`` file or a ROS 2 bag folder.
        out: the layout's folder.
        events: the events' topic (``dvs_msgs/EventArray`` or Prophesee's ``EventArray``).
        force: the force topic (``None``: an unlabeled recording).
        force_field: what to read from each force message (see
            :func:`~event_transforms.events.bags.read_bag_values`; a wrench's magnitude by default).
        stamps: ``"header"`` (default) or ``"receive"`` times for the force messages.
        role: the row's role, ``"train"`` or ``"deploy"``.
        diameter_mm: the object's size, where the table has a ``diameter_mm`` column.
        triggers: ``(camera topic, force topic)``: the same trigger pulses stamped on the
            camera's clock and on the force sensor's; the force times are moved to the
            camera's clock by the median difference (printed with its spread; the counts must
            match).
        log: called with one line saying what was read and written.

    Returns:
        The row's line number in ``recordings.csv``.

    Raises:
        ValueError: naming the bag and the topic (see the readers), a role other than train
            or deploy, a recording already in the table.
    """
    bag, out = Path(bag), Path(out)
    if role not in ("train", "deploy"):
        raise ValueError(f"role must be 'train' or 'deploy', got {role!r}")
    columns, sensor = read_bag_events(bag, events)
    if not len(columns["t"]):
        raise ValueError(f"{bag}: topic {events!r} holds no event")
    force_read = None if force is None else read_bag_values(bag, force, field=force_field, stamps=stamps)
    name = bag.stem if bag.is_file() else bag.name
    table = out / "recordings.csv"
    header = ["events", "force", "role"]
    rows: list[list[str]] = []
    if table.is_file():
        with open(table, newline="") as handle:
            found = list(csv.reader(handle))
        header, rows = [h.strip() for h in found[0]], found[1:]
        if f"events/{name}.npz" in [row[header.index("events")] for row in rows if row]:
            raise ValueError(f"{table}: events/{name}.npz is already a row; remove it to convert {bag} again")
    if "diameter_mm" in header and diameter_mm is None:
        raise ValueError(f"{table} has a diameter_mm column: give the object's size with --diameter-mm")
    (out / "events").mkdir(parents=True, exist_ok=True)
    arrays: dict[str, Any] = {"x": columns["x"], "y": columns["y"], "t": columns["t"] // 1000, "p": columns["p"]}
    if sensor is not None:
        arrays["sensor_size"] = np.asarray(sensor, dtype=np.int64)
    np.savez(out / "events" / f"{name}.npz", **arrays)
    said = f"{len(columns['t']):,} events from {events}" + (f" (sensor {sensor[0]}×{sensor[1]})" if sensor else "")
    force_cell = ""
    if force_read is not None:
        t_ns, values, what = force_read
        if triggers is not None:
            from .labels import trigger_offset

            camera, logger = (read_bag_stamps(bag, topic, stamps=stamps) for topic in triggers)
            offset, spread = trigger_offset(camera / 1000.0, logger / 1000.0,
                                            f"{bag}: trigger topics {triggers[0]!r} and {triggers[1]!r}")
            t_ns = t_ns + int(round(offset * 1000.0))
            what += (f"; force clock aligned to the camera's by {offset / 1000:+.3f} ms from {camera.size} triggers "
                     f"(spread {spread:.1f} µs)")
        (out / "force").mkdir(parents=True, exist_ok=True)
        with open(out / "force" / f"{name}.csv", "w") as handle:
            handle.write("t_us,force_n\n")
            handle.writelines(f"{t / 1000:.3f},{v!r}\n" for t, v in zip(t_ns.tolist(), values.tolist()))
        force_cell = f"force/{name}.csv"
        said += f", {what}"
    cells = {"events": f"events/{name}.npz", "force": force_cell, "role": role,
             "diameter_mm": "" if diameter_mm is None else f"{diameter_mm:g}"}
    rows.append([cells.get(h, "") for h in header])
    with atomic_write(table, "w") as handle:
        csv.writer(handle, lineterminator="\n").writerows([header, *rows])
    if log:
        log(f"{bag}: {said} -> events/{name}.npz" + (f", {force_cell}" if force_cell else "")
            + f"; row {len(rows) + 1} of {table}")
    return len(rows) + 1
