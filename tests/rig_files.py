"""Small rig files the tests write: ``.aedat4`` with trigger packets (faery's writer), HDF5
arrays, ROS bags (rosbags' writer)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest


def write_aedat4(path: Path, events: np.ndarray, sensor: tuple[int, int], triggers: np.ndarray | None = None,
                 sources: int | np.ndarray = 1) -> None:
    """``events`` (fields x, y, t, p) and trigger times ``triggers`` (µs, source ``sources``) as an
    .aedat4 file stating ``sensor`` (H, W), through faery's AEDAT4 encoder (the aedat package
    only decodes)."""
    faery = pytest.importorskip("faery")
    A = faery.aedat

    def attribute(kind: str, value: object) -> object:
        return A.DescriptionAttribute(attribute_type=kind, value=value)

    def node(i: int, name: str, type_id: str, info: dict[str, int]) -> object:
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
