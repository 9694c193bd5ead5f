"""Replay trees are checked once, at the entry, against each module's params_spec: each bad tree
found so far is a regression test, with the module, key and value named."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import event_transforms as et


@pytest.fixture
def x():
    return torch.poisson(torch.full((2, 6, 2, 8, 10), 0.8), generator=torch.Generator().manual_seed(0))


def _tree(module, x):
    return module.make_params(x.shape, generator=torch.Generator().manual_seed(0))


def test_fraction_above_one(x):
    module = et.TemporalEventShift(-1, 0.5)
    params = {**_tree(module, x), "fraction": torch.tensor([1.5, 0.5], dtype=torch.float64)}
    with pytest.raises(ValueError, match=r"TemporalEventShift: params\['fraction'\] must lie in \[0.0, 1.0\], got tensor \[1.5"):
        module(x, params=params)


def test_float_translate_shift(x):
    module = et.RandomTranslate(2)
    params = {**_tree(module, x), "shift": torch.full((2, 2), 0.5, dtype=torch.float64)}
    with pytest.raises(TypeError, match=r"RandomTranslate: params\['shift'\] must be an integer tensor, got tensor \[\[0.5"):
        module(x, params=params)


def test_nan_angle(x):
    module = et.RandomRotation(10.0)
    params = {**_tree(module, x), "angle": torch.tensor([float("nan"), 1.0], dtype=torch.float64)}
    with pytest.raises(ValueError, match=r"RandomRotation: params\['angle'\] must be finite, got tensor \[nan"):
        module(x, params=params)


def test_one_of_index_out_of_range(x):
    module = et.OneOf([et.FrameShift(1), et.RandomRotation(10.0)])
    params = {**_tree(module, x), "index": torch.tensor([5, 0])}
    with pytest.raises(ValueError, match=r"OneOf: params\['index'\] must lie in \[0, 1\], got tensor \[5, 0\]"):
        module(x, params=params)


def test_event_drop_method_unknown(x):
    module = et.RandomEventDrop(methods=("random", "area"))
    params = {**_tree(module, x), "method": torch.tensor([7, 0])}
    with pytest.raises(ValueError, match=r"RandomEventDrop: params\['method'\] must hold values in \[0, 2\], got tensor \[7, 0\]"):
        module(x, params=params)
    params["method"] = torch.tensor([1, 0])  # "time" is a method this module does not use
    with pytest.raises(ValueError, match=r"params\['method'\] must hold values in \[0, 2\]"):
        module(x, params=params)


def test_fractional_frame_shift(x):
    module = et.RandomFrameShift([-1, 1])
    params = {"shift": torch.tensor([0.5, 0.5])}
    with pytest.raises(TypeError, match=r"RandomFrameShift: params\['shift'\] must be an integer tensor, got tensor \[0.5, 0.5\]"):
        module(x, params=params)
    with pytest.raises(ValueError, match=r"RandomFrameShift: params\['shift'\] must hold values in \[-1, 1\], got tensor \[3, 1\]"):
        module(x, params={"shift": torch.tensor([3, 1])})


def test_gate_must_be_bool(x):
    module = et.RandomRotation(10.0, p=0.5)
    params = {**_tree(module, x), "apply": torch.tensor([0.1, 0.1])}
    with pytest.raises(TypeError, match=r"RandomRotation: params\['apply'\] must be a bool tensor .*got tensor \[0.1"):
        module(x, params=params)


def test_unknown_and_missing_keys(x):
    module = et.RandomRotation(10.0)
    with pytest.raises(ValueError, match=r"RandomRotation: params has unknown key\(s\) \['angles'\]; RandomRotation takes \['angle', 'apply'\]"):
        module(x, params={"angles": torch.zeros(2, dtype=torch.float64)})
    with pytest.raises(ValueError, match=r"RandomRotation: params has no entry 'angle'"):
        module(x, params={})
    nested = et.Compose([et.FrameShift(1), et.RandomRotation(5.0)])
    params = _tree(nested, x)
    params["1"]["typo"] = torch.zeros(2)
    with pytest.raises(ValueError, match=r"RandomRotation: params\['1'\] has unknown key\(s\) \['typo'\]"):
        nested(x, params=params)


def test_negative_rate(x):
    module = et.AddPoissonNoise(1.0)
    params = {**_tree(module, x), "rate_hz": torch.tensor([-1.0, 1.0], dtype=torch.float64)}
    with pytest.raises(ValueError, match=r"AddPoissonNoise: params\['rate_hz'\] must lie in \[0.0, inf\], got tensor \[-1.0"):
        module(x, params=params)


@pytest.mark.parametrize("generator", [0, np.random.default_rng(0), "seed"])
def test_generator_type(x, generator):
    with pytest.raises(TypeError, match=r"FrameShift: generator must be a torch.Generator or None"):
        et.FrameShift(1)(x, generator=generator)


@pytest.mark.parametrize("factory", [lambda: et.FrameShift(2**70), lambda: et.TemporalEventShift(-(2**70), 0.5), lambda: et.RandomFrameShift([1, 2**70])])
def test_huge_shift_named(factory):
    with pytest.raises(ValueError, match=r"shifts? must lie in \[-4611686018427387904, 4611686018427387904\], got -?1180591620717411303424"):
        factory()


def test_compose_member_changing_t_is_named(x):
    with pytest.raises(ValueError, match=r"Lambda\(<lambda>\) must keep the batch shape \(2, 6, 2, 8, 10\), got \(2, 3, 2, 8, 10\)"):
        et.Compose([lambda f: f[:, :3]])(x)


def test_dtypes_are_canonicalised_and_replay(x):
    module = et.RandomTemporalEventShift([-1, 1], (0.2, 0.8), p=0.5)
    params = _tree(module, x)
    loose = {**params, "shift": params["shift"].to(torch.int32), "fraction": params["fraction"].float().double()}
    assert torch.equal(module(x, params=loose), module(x, params=params))


def test_a_subclass_that_draws_must_declare_its_spec(x):
    with pytest.raises(TypeError, match="Scale draws parameters .* must declare them: override params_spec"):
        class Scale(et.EventTransform):
            def sample_params(self, shape, *, generator=None, metadata=None):
                return {"factor": torch.full((shape[0],), 2.0)}

            def apply_transform(self, frames, params):
                return frames * params["factor"].view(-1, 1, 1, 1, 1)

    class Declared(et.EventTransform):
        def sample_params(self, shape, *, generator=None, metadata=None):
            return {"factor": torch.full((shape[0],), 2.0)}

        def params_spec(self, shape):
            return {"factor": et.Param("float", low=0.0)}

        def apply_transform(self, frames, params):
            return frames * params["factor"].view(-1, 1, 1, 1, 1)

    with pytest.raises(ValueError, match=r"Declared: params\['factor'\] must have shape \(2,\)"):
        Declared()(x, params={"factor": torch.ones(3)})
    with pytest.raises(ValueError, match=r"Declared: params\['factor'\] must lie in \[0.0, inf\]"):
        Declared()(x, params={"factor": -torch.ones(2)})
    assert torch.equal(Declared()(x, params={"factor": torch.ones(2)}), x)
