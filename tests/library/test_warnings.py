"""Warnings a training loop can live with.

A drop that is a transform's documented meaning (rotated, jittered or shifted off the sensor or
out of the window) is counted by ``count_dropped``, never warned; a drop the caller did not ask
for (their input outside the declared sensor or window) warns with a fixed message, its counts
as attributes, at the caller's line, so Python's default filter shows it once per line.
"""

from __future__ import annotations

import warnings

import numpy as np
import torch

import event_transforms as et
from event_transforms import functional as F
from event_transforms.events import EventsOutsideSensorWarning, EventsOutsideWindowWarning

SENSOR = (20, 24)


def _streams(rng: np.random.Generator, n_streams: int, off_sensor: bool) -> list[torch.Tensor]:
    out = []
    for _ in range(n_streams):
        n = int(rng.integers(50, 200))
        x = rng.integers(0, SENSOR[1] + (3 if off_sensor else 0), n)
        y = rng.integers(0, SENSOR[0], n)
        t = np.sort(rng.integers(0, 60_000, n))
        p = rng.integers(0, 2, n)
        out.append(torch.from_numpy(np.stack([x, y, t, p], 1)))
    return out


def _loop(batches: int = 100) -> tuple[list[warnings.WarningMessage], int]:
    """A loader-like loop of ``batches`` batches through rotation, TES, jitter and binning, on
    events (the caller's own input holds events off its declared sensor) and on frames."""
    rng = np.random.default_rng(0)
    events = et.Compose([
        et.RandomRotation(30.0),
        et.SpatialJitter(1.5),
        et.RandomTemporalEventShift((-2, 2), 0.5),
        et.EventsToFrames(sensor_size=SENSOR, n_frames=6),
    ])
    frames_pipeline = et.Compose([et.RandomRotation(30.0), et.RandomFrameShift((-2, 2))])
    generator = torch.Generator().manual_seed(0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.resetwarnings()
        warnings.simplefilter("default")  # Python's own default: once per location
        with et.count_dropped() as dropped:
            for _ in range(batches):
                batch = et.EventBatch.from_streams(_streams(rng, 4, off_sensor=True), sensor_size=SENSOR,
                                                   frame_ms=10.0, t_start=0, n_frames=6)
                frames = events(batch, generator=generator)
                frames_pipeline(frames, generator=generator)
                raw = np.concatenate([s.numpy() for s in _streams(rng, 1, off_sensor=True)])
                F.events_to_frames(raw, sensor_size=SENSOR, n_frames=3, t_start=0)  # an explicit, shorter window
    return list(caught), dropped.total


def test_a_100_batch_loop_warns_at_most_once_per_cause():
    caught, dropped_by_design = _loop(100)
    causes = [type(w.message).__name__ for w in caught]
    assert sorted(causes) == ["EventsOutsideSensorWarning", "EventsOutsideSensorWarning", "EventsOutsideWindowWarning"], causes
    # two call sites of the caller's code hold input off the sensor (from_streams, events_to_frames), one of
    # them a window shorter than its input: one warning per cause and line, not one per batch
    assert len({(w.category, w.filename, w.lineno) for w in caught}) == len(caught) == 3
    assert all(w.filename == __file__ for w in caught), [(w.filename, w.lineno) for w in caught]
    assert dropped_by_design > 0  # rotation, jitter and TES dropped events by design: counted, not warned


def test_the_message_gives_the_numbers_and_the_counts_are_attributes():
    events = torch.tensor([[1, 1, 0, 1], [30, 1, 10, 0], [2, 2, 20, 1]])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        F.events_to_frames(events, sensor_size=(4, 4))
        F.events_to_frames(events[:2], sensor_size=(4, 4))
    first, second = (w.message for w in caught)
    assert str(first).startswith(EventsOutsideSensorWarning.MESSAGE) and str(second).startswith(
        EventsOutsideSensorWarning.MESSAGE)
    assert "1 of 3 events (33.3 %)" in str(first) and "fit sensor_size=(4, 31)" in str(first)
    assert "1 of 2 events (50.0 %)" in str(second)
    assert (first.dropped, first.total, first.suggested_sensor_size) == (1, 3, (4, 31))
    assert (second.dropped, second.total) == (1, 2)
    assert all(w.filename == __file__ for w in caught)


def test_numbered_messages_still_show_once_per_line_under_the_default_filter():
    with warnings.catch_warnings(record=True) as caught:
        warnings.resetwarnings()
        warnings.simplefilter("default")
        for n in range(2, 6):  # a different count each call, one line
            F.events_to_frames(torch.tensor([[30, 1, 0, 1]] * n + [[1, 1, 0, 1]]), sensor_size=(4, 4))
    assert len(caught) == 1 and "2 of 3 events" in str(caught[0].message)


def test_transforms_never_warn_for_what_they_drop_by_design():
    batch = et.EventBatch.from_streams(_streams(np.random.default_rng(1), 3, off_sensor=False), sensor_size=SENSOR,
                                       frame_ms=10.0, t_start=0, n_frames=6)
    modules = [et.RandomRotation(90.0), et.SpatialJitter(4.0), et.RandomTranslate((8, 8)), et.FrameShift(3),
               et.RandomTemporalEventShift((-3, 3), 1.0), et.RandomPerspective(0.9),
               et.RandomElastic(alpha=(20.0, 40.0), sigma=2.0)]
    for module in modules:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            with et.count_dropped() as dropped:
                out = module(batch, generator=torch.Generator().manual_seed(0))
                frames = F.bin_events(out)
        kept = int(frames.sum())
        assert kept + dropped.total == batch.num_events, type(module).__name__


def test_nothing_is_counted_outside_a_block_and_blocks_nest():
    batch = et.EventBatch.from_streams([torch.tensor([[0, 0, 0, 1], [3, 3, 0, 0]])], sensor_size=(4, 4))
    F.bin_events(F.translate(batch, torch.tensor([[0.0, 2.0]])), frame_ms=10.0)  # no block: nothing to read
    with et.count_dropped() as outer:
        with et.count_dropped() as inner:
            F.bin_events(F.translate(batch, torch.tensor([[0.0, 2.0]])), frame_ms=10.0)
        F.bin_events(F.translate(batch, torch.tensor([[0.0, -2.0]])), frame_ms=10.0)
    assert inner.counts() == {"off_sensor": 1} and outer.counts() == {"off_sensor": 2}
    assert EventsOutsideWindowWarning.MESSAGE and "dropped" in EventsOutsideWindowWarning.MESSAGE
