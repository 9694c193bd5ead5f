"""Your own recordings: a folder layout, a data set, the benchmark's data, and the simulator's export.

**The layout.** A folder holding ``recordings.csv`` (a header row, one row per recording):

==============  ==========================================================================
column          meaning
==============  ==========================================================================
``events``      path of the event file, relative to the folder (required)
``force``       path of the force CSV, relative to the folder; empty for an unlabeled
                recording (required column)
``role``        ``train`` (labelled training recordings) or ``deploy`` (recordings of the
                setup the model will meet; labelled ones are scored, unlabeled ones only
                feed :func:`~event_transforms.infer_scene`) (required)
``diameter_mm`` the object's size, for size gaps and the stretch (optional; every row then)
``object``,     free text, kept in each item's metadata (optional)
``session``
``split``       overrides the split rule below for this recording: ``train``/``holdout``
                (training role), ``val``/``test`` (deployment role) (optional)
``crop_top``,   this recording's crop window, all four or none (optional; the simulator's
``crop_left``,  export writes them: the built-in data set's fixed crop)
``crop_height``,
``crop_width``
anything else   kept as text in each item's metadata
==============  ==========================================================================

**Event files** in every form :mod:`event_transforms.events.io` reads: ``.npy`` (a structured
array with fields ``x, y, t, p`` — ``timestamp``/``on``/``polarity`` accepted, tonic's dtypes
included — or ``(N, k)`` rows, ``x, y, t, p`` unless ``columns`` (``--columns``) names another
order; read memory-mapped), ``.npz`` (arrays ``x``, ``y``, ``t``, ``p``), ``.csv`` with a
header naming the columns, Prophesee ``.dat``, and through optional extras ``.aedat4`` (the
``aedat`` package), Prophesee ``.raw`` EVT 3.0 (``evt3``) and HDF5 ``.h5``/``.hdf5`` (``h5py``:
a structured or ``(N, k)`` ``events`` dataset, Prophesee-style ``CD/events``, or one dataset per
column); ROS bags are written in the layout by :func:`convert_bag` (``event-transforms
convert``). The sensor size is the one the files state (``.aedat4``, ``.raw``, ``.dat``, HDF5
attributes, a converted ``.npz``), else ``sensor_size``, else :data:`DEFAULT_SENSOR_SIZE`; a
given size that differs from a file's is refused. Timestamps are microseconds unless
``time_unit`` (``--time-unit``) says ``"ns"``, ``"ms"`` or ``"s"``, sorted; float timestamps
with fractions spanning less than 1e6 look like seconds, and integer timestamps whose span and
count say milliseconds look like milliseconds: both are refused without a ``time_unit``.
Polarity bool, {0, 1} or {-1, 1}.

**Force files**: CSV with a header holding a time column — ``t_us`` (microseconds on the
events' clock, after the declared offset, whatever ``time_unit`` the event files use), or
``t_ns``, ``t_ms``, ``t_s`` (the unit read from the name), or ``t``/``time``/``timestamp``
with ``force_time_unit`` — and the label: ``force_n`` (newtons), the column ``force_column``
names, or with ``force_column="magnitude"`` the norm of ``fx, fy, fz``; sorted by time, at any
rate; each conversion is said once to ``log``. The force clock runs ``force_offset_ms`` behind
the camera's: a sample at ``t_us`` on the force clock is at ``t_us + 1000 · force_offset_ms``
on the events' clock (default 0); ``sync="triggers"`` measures that lag per recording from the
event file's trigger events and the force CSV's ``trigger`` column (non-zero on the samples at
which the sync line was raised).

**Frames and labels.** A recording is binned from its first event rounded down to the bin
grid (the ``"floor"`` rule of :func:`~event_transforms.functional.events_to_frames`) to the
bin of its last event, in ``frame_ms`` bins, cropped and sum-pooled. A frame's label is the
mean of the force samples inside its bin ``[start, start + frame_ms)``; a bin holding no
sample (force sampled more slowly than the frames) takes the force linearly interpolated at
its centre. The samples must cover the recording: the first at or before the end of the first
bin, the last at or after the start of the last bin. A recording is then cut into windows of
``frames`` (T) frames every ``stride`` frames (default T); frames after the last whole window
are left out (counted in :attr:`RecordingSet.left_out_frames`).

**Splits** (never a recording on both sides; a folder of training recordings only loads
with ``split="train"``, ``"holdout"`` or ``role="train"``): training-role recordings in the order of
``recordings.csv``: the last third (``n // 3``) are the *hold-out* of the stopping rule, the
rest train. Labelled deployment recordings: the first fifth (``ceil(n / 5)``, at least one)
validate, the rest test; at least two are needed. Unlabeled deployment recordings are used
only as frames for :func:`~event_transforms.infer_scene` (never scored). A ``split`` column
overrides the rule per recording.

**Crop.** ``crop=None`` and no crop columns: the contact area's bounding box over the training
recordings (pixels whose event total stands out from the background, see :func:`contact_crop`),
rounded out to multiples of ``pool``.

**Cache.** Each recording's frames and labels are binned once into the package cache
(:func:`~event_transforms.tactile.datasets.default_cache_dir` ``/recordings``), keyed by a hash
of the event and force files' bytes and of the settings, written to a temporary file and
renamed (nothing half-written stays); a cache file that cannot be read is named, deleted and
rebuilt. Binning reads the event file in chunks (memory-mapped ``.npy``) through
:func:`~event_transforms.functional.iter_frames`, so memory is bounded by a chunk plus the
recording's frames, whatever the file's size.

Example:
    >>> import tempfile, numpy as np
    >>> root = Path(tempfile.mkdtemp())
    >>> rng = np.random.default_rng(0)
    >>> rows = ["events,force,role,diameter_mm"]
    >>> for k, role in enumerate(["train"] * 3 + ["deploy"] * 2):
    ...     events = np.zeros(4000, dtype=[("x", "<i2"), ("y", "<i2"), ("t", "<i8"), ("p", "<i1")])
    ...     events["t"] = np.sort(rng.integers(0, 200_000, 4000))
    ...     events["x"], events["y"] = rng.integers(10, 30, 4000), rng.integers(5, 25, 4000)
    ...     events["p"] = rng.integers(0, 2, 4000)
    ...     np.save(root / f"r{k}.npy", events)
    ...     t = np.arange(0, 200_000, 2_000)  # 500 Hz
    ...     np.savetxt(root / f"r{k}.csv", np.c_[t, 5 + np.sin(t / 3e4)], delimiter=",",
    ...                header="t_us,force_n", comments="")
    ...     rows.append(f"r{k}.npy,r{k}.csv,{role},15")
    >>> _ = (root / "recordings.csv").write_text("\\n".join(rows) + "\\n")
    >>> train = RecordingSet(root, split="train", sensor_size=(40, 40), frames=10, pool=2,
    ...                      cache=root / "cache")
    >>> frames, force, meta = train[0]
    >>> len(train), tuple(frames.shape), tuple(force.shape), meta["diameter_mm"], train.crop
    (4, (10, 2, 12, 12), (10,), 15.0, (3, 8, 24, 24))
"""

from __future__ import annotations

__all__ = [
    "SPLITS",
    "EventScan",
    "RecordingEntry",
    "DEFAULT_SENSOR_SIZE",
    "convert_bag",
    "RecordingScene",
    "RecordingSet",
    "RecordingSettings",
    "contact_crop",
    "content_hash",
    "export_scene",
    "frame_labels",
    "load_recording_data",
    "read_events",
    "read_force",
    "read_table",
    "scan_events",
]

from pathlib import Path


from ...events.io import read_events  # re-export: the readers live in event_transforms.events.io
from .cache import content_hash
from .dataset import RecordingSet
from .convert import convert_bag
from .export import export_scene
from .labels import frame_labels, read_force
from .layout import DEFAULT_SENSOR_SIZE, SPLITS, RecordingEntry, RecordingSettings, read_table
from .scan import EventScan, contact_crop, scan_events
from .protocol_data import RecordingScene, load_recording_data

_ = Path  # the module docstring's example uses Path
