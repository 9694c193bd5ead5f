"""One declaration per operation: the public dispatcher and the module check the same Param.

Each row of ``OPS`` names a public dispatcher with per-sample arguments, its declaration (the
``*_SPEC`` dict or ``*_spec(shape)`` function beside it in ``functional/<topic>.py``) and a
module that returns it from ``params_spec``. The tests walk the declaration: every bad value
it implies (not finite, out of range, wrong shape, wrong dtype kind, a broken rule) is
refused by both paths with an error naming the operation or module, the argument and the
value; every range end is accepted by both. A new operation is covered by adding a row.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import pytest
import torch

import event_transforms as et
from event_transforms import functional as F
from event_transforms._params import Param, check_args

from tests.support.event_data import make_batch

# the topic files (``functional.affine`` is also the name of the ``affine`` dispatcher)
affine, drop, elastic, geometry, mixing, noise, perspective, stretch, temporal, timestamps = (
    importlib.import_module(f"event_transforms.functional.{topic}")
    for topic in ("affine", "drop", "elastic", "geometry", "mixing", "noise", "perspective", "stretch", "temporal", "timestamps")
)

B, T, H, W = 3, 6, 11, 17  # events: tests/event_data's sensor (11, 17) and T = 6
SHAPE = torch.Size((B, T, 2, H, W))


@dataclass
class Op:
    name: str
    spec: Callable[[torch.Size], dict[str, Param]]
    module: Callable[[], et.EventTransform] | None
    events: bool = False  # the dispatcher takes an EventBatch only
    fixed: dict[str, Any] = field(default_factory=dict)  # its other arguments
    defaults: dict[str, Any] = field(default_factory=dict)  # per-sample values no module draws
    functional_only: tuple[str, ...] = ()  # declared arguments the module takes as settings

    def __str__(self) -> str:
        return self.name


def _elastic_noise() -> torch.Tensor:
    return torch.zeros(B, 2, H, W)


OPS = [
    Op("rotate", lambda s: affine.ROTATE_SPEC, lambda: et.Rotate(10.0)),
    Op("resize", lambda s: affine.RESIZE_SPEC, lambda: et.Resize(1.2)),
    Op("affine", lambda s: affine.AFFINE_SPEC, lambda: et.Affine(angle=5.0, scale=1.1, shear=(10.0, 0.0))),
    Op("perspective", lambda s: perspective.PERSPECTIVE_SPEC, lambda: et.RandomPerspective(0.3)),
    Op("elastic", lambda s: {"alpha": elastic.elastic_spec(s)["alpha"]}, lambda: et.RandomElastic(),
       fixed={"noise": _elastic_noise()}),
    Op("drop_random", lambda s: drop.DROP_RANDOM_SPEC, lambda: et.RandomEventDrop(),
       fixed={"generator": torch.Generator().manual_seed(0)}),
    Op("drop_by_time", lambda s: drop.DROP_BY_TIME_SPEC, lambda: et.RandomEventDrop()),
    Op("drop_by_area", lambda s: drop.DROP_BY_AREA_SPEC, lambda: et.RandomEventDrop()),
    Op("refractory_period", lambda s: drop.REFRACTORY_PERIOD_SPEC, lambda: et.RefractoryPeriod(), events=True),
    Op("decimation", lambda s: drop.DECIMATION_SPEC, lambda: et.Decimation(), events=True),
    Op("translate", lambda s: geometry.TRANSLATE_SPEC, lambda: et.RandomTranslate(2)),
    Op("crop", lambda s: geometry.crop_spec(s, (5, 4)), lambda: et.RandomCrop((5, 4)), fixed={"size": (5, 4)}),
    Op("spatial_jitter", lambda s: geometry.SPATIAL_JITTER_SPEC, lambda: et.SpatialJitter(), events=True),
    Op("frame_shift", lambda s: temporal.FRAME_SHIFT_SPEC, lambda: et.FrameShift(-1)),
    Op("temporal_event_shift", lambda s: temporal.TEMPORAL_EVENT_SHIFT_SPEC, lambda: et.TemporalEventShift(-1, 0.5)),
    Op("crop_time", lambda s: temporal.crop_time_spec(s, 4), lambda: et.RandomCropTime(4), fixed={"length": 4}),
    Op("time_jitter", lambda s: timestamps.TIME_JITTER_SPEC, lambda: et.TimeJitter(), events=True),
    Op("time_skew", lambda s: timestamps.TIME_SKEW_SPEC, lambda: et.TimeSkew(), events=True),
    Op("cutout", lambda s: mixing.CUTOUT_SPEC, lambda: et.Cutout(3)),
    Op("add_poisson_noise", lambda s: noise.ADD_POISSON_NOISE_SPEC, lambda: et.AddPoissonNoise((0.1, 10.0)), fixed={"frame_ms": 1.0}),
    Op("cutmix", lambda s: mixing.cutmix_spec(s), lambda: et.CutMix()),
    Op("mixup", lambda s: mixing.mixup_spec(s), lambda: et.MixUp(), events=True),
    Op("stretch", lambda s: stretch.STRETCH_SPEC, lambda: et.Stretch(1.3), defaults={"axis": 30.0},
       functional_only=("axis",)),
]


def _inputs(op: Op) -> Any:
    if op.events:
        return make_batch(B)
    return torch.randint(0, 3, tuple(SHAPE)).to(torch.float32)


def _tree(op: Op) -> dict[str, Any]:
    module = op.module()
    return module, dict(module.make_params(SHAPE, generator=torch.Generator().manual_seed(1)))


def _values(op: Op) -> dict[str, Any]:
    """Valid per-sample arguments: what the module draws, and the row's defaults."""
    _, tree = _tree(op)
    spec = op.spec(SHAPE)
    return {k: tree[k] if k in tree else op.defaults[k] for k in spec}


def _call(op: Op, inputs: Any, values: dict[str, Any]) -> Any:
    return getattr(F, op.name)(inputs, **op.fixed, **values)


def _full(param: Param, value: float, dtype: torch.dtype | None = None) -> torch.Tensor:
    kind = {"float": torch.float64, "int": torch.int64, "bool": torch.bool}[param.kind]
    return torch.full((B, *param.shape), value, dtype=dtype or kind)


def _bad_values(param: Param) -> list[tuple[str, torch.Tensor, type, str]]:
    """(what, value, error, message) for every bad value the declaration implies."""
    bad: list[tuple[str, torch.Tensor, type, str]] = [
        ("shape", torch.zeros(B + 1, *param.shape, dtype=torch.float64 if param.kind == "float" else torch.int64),
         ValueError, "shape"),
        ("bool", torch.zeros(B, *param.shape, dtype=torch.bool), TypeError, ""),
    ]
    if param.kind == "float":
        bad.append(("nan", _full(param, math.nan), ValueError, "must be finite"))
        bad.append(("inf", _full(param, math.inf), ValueError, "must be finite"))
    if param.kind == "int":
        bad.append(("fractional", _full(param, 0.5, torch.float64), TypeError, "integer"))
    if param.low is not None:
        below = param.low if param.low_open else param.low - 1
        bad.append(("below", _full(param, below), ValueError, "must lie in"))
    if param.high is not None and param.high < 2**63 - 1:
        above = param.high if param.high_open else param.high + 1
        bad.append(("above", _full(param, above), ValueError, "must lie in"))
    if param.rule is not None:
        bad.append(("rule", torch.zeros(B, *param.shape, dtype=torch.float64), ValueError, "must"))
    return bad


def _bad_cases() -> list[Any]:
    cases = []
    for op in OPS:
        for name, param in op.spec(SHAPE).items():
            for what, value, error, message in _bad_values(param):
                cases.append(pytest.param(op, name, value, error, message, id=f"{op.name}-{name}-{what}"))
    return cases


def _ends(param: Param) -> list[float]:
    return [v for v, is_open in ((param.low, param.low_open), (param.high, param.high_open)) if v is not None and not is_open]


def _end_cases() -> list[Any]:
    return [pytest.param(op, name, end, id=f"{op.name}-{name}-{end}")
            for op in OPS for name, param in op.spec(SHAPE).items() for end in _ends(param)]


@pytest.mark.parametrize("op", OPS, ids=str)
def test_the_module_returns_the_declaration(op):
    module = op.module()
    declared = op.spec(SHAPE)
    own = module.params_spec(SHAPE)
    for name, param in declared.items():
        if name in op.functional_only:
            assert name not in own
            continue
        assert own[name] == param, f"{type(module).__name__}.params_spec()[{name!r}] is not {op.name}'s declaration"


@pytest.mark.parametrize("op, name, value, error, message", _bad_cases())
def test_a_bad_value_is_refused_by_both_paths_by_name(op, name, value, error, message):
    inputs = _inputs(op)
    values = _values(op)
    values[name] = value
    with pytest.raises(error, match=f"{op.name}: {name} .*{message}") as raised:
        _call(op, inputs, values)
    assert "got" in str(raised.value)  # the value seen
    if name in op.functional_only:
        return
    module, tree = _tree(op)
    tree[name] = value
    with pytest.raises(error, match=rf"{type(module).__name__}: params\['{name}'\] .*{message}"):
        module(inputs, params=tree)


@pytest.mark.parametrize("op, name, end", _end_cases())
def test_range_ends_are_accepted_by_both_paths(op, name, end):
    inputs = _inputs(op)
    param = op.spec(SHAPE)[name]
    values = _values(op)
    values[name] = _full(param, end)
    _call(op, inputs, values)
    if param.shape == ():  # a number for every sample is the same call
        values[name] = int(end) if param.kind == "int" else float(end)
        _call(op, inputs, values)
    if name in op.functional_only:
        return
    module, tree = _tree(op)
    tree[name] = _full(param, end)
    module(inputs, params=tree)


@pytest.mark.parametrize("op", OPS, ids=str)
def test_every_accepted_form_gives_the_same_call(op):
    """A number, a list, a numpy array and a (B, *shape) tensor of the same values are one call."""
    np = pytest.importorskip("numpy")
    values = _values(op)
    spec = op.spec(SHAPE)
    forms = [{k: torch.as_tensor(v) for k, v in values.items()},
             {k: torch.as_tensor(v).tolist() for k, v in values.items()},
             {k: np.asarray(torch.as_tensor(v).tolist()) for k, v in values.items()}]
    checked = [check_args(op.name, spec, B, **form) for form in forms]
    for other in checked[1:]:
        assert all(torch.equal(checked[0][k], other[k]) for k in spec)


def test_mix_labels_checks_its_declaration():
    labels = torch.rand(B, T)
    with pytest.raises(ValueError, match=r"mix_labels: partner must lie in \[0, 2\], got \[0, 1, 3\]"):
        F.mix_labels(labels, [0, 1, 3], 0.5)
    with pytest.raises(ValueError, match=r"mix_labels: weight must lie in \[0.0, 1.0\], got 1.5"):
        F.mix_labels(labels, [0, 1, 2], 1.5)
    F.mix_labels(labels, [0, 1, 2], [0.0, 1.0, 0.5])


def test_open_bounds_and_rules_say_so():
    frames = torch.ones(1, 2, 5, 5)
    with pytest.raises(ValueError, match=r"resize: scale must lie in \(0.0, inf\], got 0.0"):
        F.resize(frames, 0.0)
    with pytest.raises(ValueError, match=r"affine: shear must lie in \(-90.0, 90.0\), got \(90.0, 0.0\)"):
        F.affine(frames, shear=(90.0, 0.0))
    with pytest.raises(ValueError, match="perspective: corners must make a convex quadrilateral"):
        F.perspective(frames, [[0, 0], [4, 4], [0, 4], [4, 0]])
    with pytest.raises(ValueError, match=r"RandomPerspective: params\['corners'\] must make a convex quadrilateral"):
        et.RandomPerspective()(frames, params={"corners": torch.tensor([[[0.0, 0], [4, 4], [0, 4], [4, 0]]])})
