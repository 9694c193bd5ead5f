"""Small rig files the tests write: ``.aedat4`` with trigger packets (faery's writer), ROS bags
(rosbags' writer), skipping the test when the writer's package is missing."""

from __future__ import annotations

from typing import Any

import pytest

from event_transforms import _fixtures


def write_aedat4(*args: Any, **kwargs: Any) -> None:
    pytest.importorskip("faery")
    _fixtures.write_aedat4(*args, **kwargs)


def write_bag(*args: Any, **kwargs: Any) -> None:
    pytest.importorskip("rosbags")
    _fixtures.write_bag(*args, **kwargs)
