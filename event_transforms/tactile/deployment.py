"""A model a user keeps: train on a folder of recordings, save a checkpoint, stream force estimates.

:func:`train_model` trains one reference :class:`~event_transforms.tactile.models.ForceRegressor`
by the protocol's rules: it calls the protocol's one trainer,
:func:`~event_transforms.tactile.training.train` (one-cycle learning rate, clipping, forces
scaled by the training mean and standard deviation, the weights with the lowest MSE on the
training role's hold-out recordings) with no augmentation, the inferred policy or any method name, and
returns it with its preprocessing (``frame_ms``, ``crop``, ``pool``, sensor size, force offset,
force scaling), which :meth:`ForceRegressor.save` writes beside the weights.
:func:`predict_stream` reads an event file of any length in chunks, bins it with
:func:`~event_transforms.functional.iter_frames` and runs :meth:`ForceRegressor.step` frame by
frame, writing ``t_us,force_n`` (each frame's centre, on the force files' clock) and timing
every step.
"""

from __future__ import annotations

__all__ = ["train_model", "predict_stream"]

import math
import os
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ._files import atomic_write
from .models import ForceRegressor


def train_model(
    data: Any,
    method: str = "none",
    *,
    steps: int = 300,
    batch_size: int = 8,
    lr: float = 1e-2,
    eval_every: int = 50,
    hidden_channels: tuple[int, ...] = (4,),
    input_pool: int = 14,
    seed: int = 0,
    device: str = "cpu",
    progress: bool | None = False,
) -> tuple[ForceRegressor, dict[str, Any]]:
    """Train one model on ``data`` (a :class:`~event_transforms.tactile.copies.SceneData`,
    e.g. from :func:`~event_transforms.tactile.recordings.load_recording_data`).

    Args:
        data: training, hold-out, validation and test sets.
        method: ``"none"``, ``"inferred"`` or any method name of
            :func:`~event_transforms.tactile.methods.parse_method` (one synthetic copy per item).
        steps, batch_size, lr, eval_every: the protocol's training settings.
        hidden_channels, input_pool: the model's size (default: the quick configuration's).
        seed: initial weights, batch order and augmentation draw.
        device: where to train; the model comes back on the CPU.
        progress: a progress bar (``None``: when stderr is a terminal).

    Returns:
        The model (eval mode) and a summary: the kept step, hold-out, validation and test MSE
        (the hold-out MSE is NaN, and the final weights are kept, without a hold-out set:
        :func:`~event_transforms.tactile.protocol.limits.holdout_note` says why).

    Raises:
        ValueError: ``batch_size`` larger than the training windows (before any training).
    """
    from .training import evaluate, mse, train

    if batch_size > len(data.train):  # before any training, named as this interface spells it
        raise ValueError(f"batch_size={batch_size} is more than the {len(data.train)} training windows: a step would "
                         f"repeat windows within its batch; give batch_size={len(data.train)} or fewer")
    trained = train(data, [method], [seed], steps=steps, batch_size=batch_size, lr=lr, eval_every=eval_every,
                    hidden_channels=tuple(hidden_channels), input_pool=input_pool, device=device, progress=progress,
                    description=f"train {method}")
    scores = {}
    for split in ("val", "test"):
        if not len(getattr(data, split)):  # a folder of training recordings only: nothing to score
            scores[f"{split}_mse"] = math.nan
            continue
        pred, target = evaluate(trained.model, getattr(data, split))
        scores[f"{split}_mse"] = mse(pred[0], target)
    record = trained.result.members[0]
    holdout = trained.holdout
    model = trained.model.to("cpu").member(0).eval()
    summary = {"method": method, "seed": seed, "steps": steps, "kept_step": record.best_step if holdout else steps,
               "holdout_mse": record.selected_val_loss if holdout else math.nan, **scores,
               "force_offset": trained.force_offset, "force_scale": trained.force_scale,
               "train_items": trained.train_items[0]}
    return model, summary


def predict_stream(
    model: ForceRegressor,
    events: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    chunk_size: int = 2**16,
    sensor_size: tuple[int, int] | None = None,
    time_unit: str | None = None,
    columns: str | None = None,
    log: Any = None,
) -> dict[str, Any]:
    """Stream an event file through ``model`` (binned as its ``preprocessing`` says, its
    timestamps read in the training recordings' ``time_unit``) and write ``t_us,force_n`` per
    frame to ``out``.

    ``t_us`` is each frame's centre on the force files' clock (the events' clock minus the
    checkpoint's ``force_offset_ms``), so the output reads back as a force file of the layout.

    Args:
        model: a model with its ``preprocessing`` (a checkpoint of ``event-transforms train``).
        events: the event file.
        out: the CSV written.
        chunk_size: events read per chunk.
        sensor_size: the file's sensor ``(H, W)`` (default: the size the file states, else the
            model's); another grid than the model's is read through the model's crop where the
            crop lies inside it (said in one line to ``log``), else refused.
        time_unit, columns: how the file's timestamps and ``(N, k)`` columns read (default:
            the training recordings' settings).
        log: called with one line when the grid differs from the model's.

    Returns:
        ``frames``, ``events``, and the per-step latency ``p50_ms``/``p99_ms``/``mean_ms``.
    """
    from ..functional import iter_frames
    from ..events.io import EventFile
    from .recordings.scan import scan_events

    settings = getattr(model, "preprocessing", None) or {}
    missing = [k for k in ("frame_ms", "crop", "pool", "sensor_size") if k not in settings]
    if missing:
        raise ValueError(f"the model's checkpoint holds no preprocessing {missing}; train it with `event-transforms train`")
    path = Path(events)
    if not path.is_file():
        raise ValueError(f"events file {str(path)!r} does not exist")
    trained = (int(settings["sensor_size"][0]), int(settings["sensor_size"][1]))
    source = EventFile(path, columns=columns if columns is not None else settings.get("columns"))
    given = None if sensor_size is None else (int(sensor_size[0]), int(sensor_size[1]))
    if given is not None and source.sensor_size is not None and given != source.sensor_size:
        raise ValueError(f"{path}: the file states a sensor of (H, W) = {source.sensor_size}, but "
                         f"sensor_size={given}; leave sensor_size out to use the file's")
    sensor = given or source.sensor_size or trained
    top, left, height, width = (int(v) for v in settings["crop"])
    crop = (top, left, height, width)
    if sensor != trained:
        if crop[0] + crop[2] > sensor[0] or crop[1] + crop[3] > sensor[1]:
            raise ValueError(f"the model was trained on a {trained} (H, W) sensor with crop {crop}, which does not fit "
                             f"this file's {sensor} sensor: train a model on recordings of this camera")
        if log:
            log(f"the model was trained on a {trained} (H, W) sensor, this file's is {sensor}: the model's crop {crop} "
                "is read from it (events outside the crop ignored)")
    time_unit = time_unit or settings.get("time_unit")  # default: the training recordings' unit (None: µs)
    scan = scan_events(source, sensor, str(path), time_unit)  # checked first: sorted, inside the sensor, units
    frame_ms = float(settings["frame_ms"])
    frame_us = frame_ms * 1000.0
    t0 = (scan.t_min // frame_us) * frame_us
    offset_us = 1000.0 * float(settings.get("force_offset_ms", 0.0))
    latencies = []
    state = None
    count = 0
    with torch.no_grad(), atomic_write(out) as handle:
        handle.write("t_us,force_n\n")
        frames = iter_frames(source.chunks(chunk_size), sensor_size=sensor, t_start=t0, frame_ms=frame_ms,
                             crop=crop, pool=int(settings["pool"]), time_unit=time_unit or "us")
        for frame in frames:
            tick = time.perf_counter()
            force, state = model.step(frame.unsqueeze(0), state)
            latencies.append(time.perf_counter() - tick)
            centre = t0 + (count + 0.5) * frame_us - offset_us
            handle.write(f"{centre:.0f},{float(force[0]):.9g}\n")
            count += 1
    ms = np.array(latencies) * 1000.0
    return {"frames": count, "events": scan.events, "p50_ms": float(np.percentile(ms, 50)),
            "p99_ms": float(np.percentile(ms, 99)), "mean_ms": float(ms.mean())}
