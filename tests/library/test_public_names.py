"""One list of public names: ``__all__``, the lazy top-level names, the transform table of docs/transforms.md
and the shared batteries (frames and events) must agree, so adding a transform cannot skip one."""

from __future__ import annotations

import inspect
import re
from pathlib import Path

import event_transforms as et
from event_transforms import functional as F
from event_transforms import transforms as T
from event_transforms.functional._dispatch import _KERNELS
from event_transforms.events.batch import EventBatch

from . import test_battery, test_event_batch, test_shape_battery
from tests.support.checkers import H, W

ROOT = Path(__file__).resolve().parents[2]
#: Public names of ``transforms`` that are not transforms of frames or events.
NOT_TRANSFORMS = {"Lambda"}
#: What writing a transform needs: event_transforms.authoring, apart from the transforms (issue 44).
AUTHORING = {"EventTransform", "Param", "Params", "as_transform", "check_args", "slice_params"}
#: What a user of the application calls: event_transforms.tactile.__all__ (issue 44).
TACTILE = {"main", "ForceRegressor", "RecordingSet", "RecordingSettings", "load_recording_data", "export_scene",
           "convert_bag", "ProtocolConfig", "run_protocol", "load_scene_data", "get_scene", "train_model",
           "predict_stream", "run_verdicts", "compare_verdicts"}
CONTAINERS = {"Compose", "OneOf", "RandomApply"}
#: Take events but change the sensor or the grid, which the event battery's checks assume kept:
#: their event kernels are tested in TestOnEvents of their topic file (crops against frames).
RESHAPING = {"RandomCrop", "CenterCrop", "CropTime", "RandomCropTime"}


def transform_classes() -> dict[str, type]:
    return {
        name: getattr(T, name) for name in T.__all__
        if name not in NOT_TRANSFORMS and inspect.isclass(getattr(T, name))
    }


def readme_table() -> dict[str, str]:
    """Class name -> the *frames / events* cell, for every class named in the README's transform table."""
    text = (ROOT / "docs" / "transforms.md").read_text()
    header = "| module | paper / source | frames / events | what it does |"
    assert header in text, "docs/transforms.md has no transform table with a frames / events column"
    rows = text.split(header, 1)[1].split("\n\n", 1)[0].strip().splitlines()[1:]
    out = {}
    for row in rows:
        cells = [c.strip() for c in row.strip("|").split(" | ")]
        for name in re.findall(r"`([A-Z]\w*)", cells[0]):
            out[name] = cells[2]
    return out


def battery_types(factories: dict, *args) -> set[str]:
    return {type(factory(*args)).__name__ for factory in factories.values()}


def test_every_transform_is_a_lazy_top_level_name():
    """``transforms.__all__`` is the one list: the top level serves each of its names."""
    assert set(T.__all__) <= set(et.__all__)
    for name in T.__all__:
        assert getattr(et, name) is getattr(T, name)
    assert {"EventBatch", "collate_events", "Scene", "infer_scene"} <= set(et.__all__)


def test_readme_table_lists_every_transform():
    table = readme_table()
    missing = set(transform_classes()) - set(table)
    assert not missing, f"transforms missing from the transform table (docs/transforms.md): {sorted(missing)}"
    unknown = set(table) - set(transform_classes()) - {"Lambda"}
    assert not unknown, f"transform table (docs/transforms.md) names that are not transforms: {sorted(unknown)}"


def test_batteries_cover_the_readme_table():
    """Every transform with a frame kernel runs the frame battery; every transform the table
    marks as taking events runs the event battery, and no other."""
    table = readme_table()
    frames = battery_types(test_battery.FACTORIES, 6, H, W) | battery_types(test_shape_battery.SHAPE_FACTORIES, 6, H, W)
    events = battery_types(test_event_batch.FACTORIES)
    for name in transform_classes():
        cell = table[name]
        if cell.startswith(("frames", "both")) and name != "EventsToFrames":
            assert name in frames, f"{name} takes frames but runs no frame battery"
        takes_events = cell.startswith(("events", "both")) and name not in CONTAINERS | RESHAPING | {"EventsToFrames"}
        assert (name in events) == takes_events, f"{name}: docs/transforms.md says {cell!r}, event battery has it: {name in events}"


def test_functional_all_holds_every_dispatcher_and_kernel():
    names = set(F.__all__)
    assert "stretch" in names and "stretch_frames" in names
    for dispatcher, kernels in _KERNELS.items():
        assert dispatcher.__name__ in names, f"dispatcher {dispatcher.__name__} is not in functional.__all__"
        for input_type, kernel in kernels.items():
            suffix = "_events" if input_type is EventBatch else "_frames"
            assert kernel.__name__ == dispatcher.__name__ + suffix, (dispatcher.__name__, kernel.__name__)
            assert kernel.__name__ in names and getattr(F, kernel.__name__) is kernel
    assert len(names) == len(F.__all__), "functional.__all__ holds a name twice"


def test_authoring_names_have_their_own_namespace():
    """The transforms are what ``et.__all__`` and ``transforms.__all__`` list; the names for writing
    one are in ``event_transforms.authoring`` (documented), still importable where they were."""
    from event_transforms import authoring

    assert set(authoring.__all__) == AUTHORING
    assert not AUTHORING & set(et.__all__) and not AUTHORING & set(T.__all__)
    assert "authoring" in et.__all__
    for name in AUTHORING:
        assert getattr(et, name) is getattr(authoring, name)  # the old spelling still works
    for name in ("EventTransform", "Param", "Params", "as_transform"):
        assert getattr(T, name) is getattr(authoring, name)
    assert authoring.slice_params.__doc__ and "Example" in authoring.slice_params.__doc__
    assert "::: event_transforms.authoring" in (ROOT / "docs" / "api" / "index.md").read_text()
    assert "from event_transforms.authoring import slice_params" in (ROOT / "docs" / "transforms.md").read_text()


def test_tactile_all_lists_what_a_user_calls():
    from event_transforms import tactile
    from event_transforms.tactile import copies, protocol, report

    assert set(tactile.__all__) == TACTILE
    for name in tactile.__all__:
        assert getattr(tactile, name) is not None
    assert tactile.ForceRegressor.__name__ == "ForceRegressor" and callable(tactile.main)
    # the protocol's internals stay importable from their modules, not from the application's namespace
    assert callable(copies.paired_batches) and callable(report.format_budget_check)
    # the protocol's namespace is the protocol's: its neighbours' names are imported from their modules
    assert set(protocol.__all__) == {"ProtocolConfig", "run_protocol", "plan_run", "check_run_limits", "run_unit",
                                     "PROGRESS_LEGEND"}
    assert not hasattr(protocol, "paired_batches") and not hasattr(protocol, "format_report")
    assert not {"paired_batches", "format_budget_check", "run_unit", "plan_run"} & set(tactile.__all__)
