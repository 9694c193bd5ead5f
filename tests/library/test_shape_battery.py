"""The battery for modules whose output shape differs from the input's (crops that change
H×W, sum-pooling, temporal crops). They cannot gate samples with ``p`` (a batch has one
shape), so ``test_battery.py``'s gate and shape checks do not apply; everything else does:
dtypes, hard cases, B = 0, T = 1, replay under other global seeds, params trees, pickling."""

from __future__ import annotations

import pickle

import pytest
import torch

import event_transforms as et
from event_transforms.transforms.base import slice_params

from tests.support.topics import collect
from tests.support.checkers import H, W, check_not_modified, sparse_frames

# name -> factory: each topic test file holds its own entries (SHAPE_BATTERY in test_<topic>.py)
SHAPE_FACTORIES = collect("SHAPE_BATTERY")
NAMES = sorted(SHAPE_FACTORIES)
DTYPES = [torch.float32, torch.float16, torch.bfloat16, torch.float64, torch.uint8, torch.int16, torch.int32, torch.int64]
# conserve every event (the others may cut some away)
CONSERVING = {"DownsampleKeep"}


def run(name, frames, seed=0):
    t, _, h, w = frames.shape[-4:]
    module = SHAPE_FACTORIES[name](t, h, w)
    out = module(frames, generator=torch.Generator().manual_seed(seed))
    batch = frames if frames.dim() == 5 else frames.unsqueeze(0)
    expected = module.output_shape(batch.shape)
    assert out.shape == (expected if frames.dim() == 5 else expected[1:])
    return out


def check(out, frames, dtype=None):
    assert out.dtype == (frames.dtype if dtype is None else dtype) and out.device == frames.device
    if out.numel():
        assert bool((out.double() >= 0).all()) and bool(out.double().isfinite().all())
    assert float(out.double().sum()) <= float(frames.double().sum()) + 1e-6


@pytest.mark.parametrize("name", NAMES)
class TestShapeBattery:
    @pytest.mark.parametrize("dtype", DTYPES)
    def test_dtypes(self, name, dtype):
        frames = sparse_frames(3, 6, 2, H, W, density=0.2, dtype=dtype)
        check(check_not_modified(lambda x: run(name, x), frames), frames)

    def test_empty_frames(self, name):
        frames = torch.zeros(2, 5, 2, H, W)
        assert run(name, frames).sum() == 0

    def test_single_event(self, name):
        frames = torch.zeros(1, 5, 2, H, W, dtype=torch.int32)
        frames[0, 2, 1, 8, 5] = 1
        out = run(name, frames)
        check(out, frames)
        if name in CONSERVING:
            assert int(out.sum()) == 1

    def test_zero_batch(self, name):
        frames = torch.zeros(0, 5, 2, H, W, dtype=torch.int16)
        assert run(name, frames).dtype == torch.int16

    @pytest.mark.parametrize("shape", [(3, 1, 2, H, W), (2, 4, 2, 1, W), (2, 4, 2, H, 1), (2, 4, 2, 1, 1), (2, 4, 2, 70, 75)])
    def test_odd_shapes(self, name, shape):
        frames = sparse_frames(*shape, density=0.3)
        check(run(name, frames), frames)

    def test_single_sequence_equals_batch_of_one(self, name):
        frames = sparse_frames(6, 2, H, W, density=0.2)
        assert torch.equal(run(name, frames, seed=5), run(name, frames.unsqueeze(0), seed=5)[0])

    def test_replay_ignores_the_global_rng(self, name):
        frames = sparse_frames(4, 6, 2, H, W, density=0.2, dtype=torch.int32)
        module = SHAPE_FACTORIES[name](6, H, W)
        params = module.make_params(frames.shape, generator=torch.Generator().manual_seed(1))
        assert all(v.shape[0] == 4 and v.device.type == "cpu" for v in params.values())
        torch.manual_seed(0)
        first = module(frames, params=params)
        torch.manual_seed(12345)
        assert torch.equal(module(frames, params=params), first)
        assert torch.equal(module(frames, generator=torch.Generator().manual_seed(1)), first)

    def test_batched_equals_per_sample_given_params(self, name):
        frames = sparse_frames(3, 6, 2, H, W, density=0.2)
        module = SHAPE_FACTORIES[name](6, H, W)
        params = module.make_params(frames.shape, generator=torch.Generator().manual_seed(4))
        batched = module(frames, params=params)
        for b in range(3):
            alone = module(frames[b : b + 1], params=slice_params(params, torch.tensor([b])))
            assert torch.equal(alone[0], batched[b])

    def test_pickle(self, name):
        frames = sparse_frames(3, 6, 2, H, W, density=0.2)
        module = SHAPE_FACTORIES[name](6, H, W)
        clone = pickle.loads(pickle.dumps(module))
        g = lambda: torch.Generator().manual_seed(3)  # noqa: E731
        assert torch.equal(module(frames, generator=g()), clone(frames, generator=g()))
        assert repr(clone) == repr(module)

    def test_bad_rank_and_polarity(self, name):
        module = SHAPE_FACTORIES[name](6, H, W)
        with pytest.raises(ValueError, match=r"got \(6, 3, 17, 11\)"):
            module(torch.zeros(6, 3, H, W))
        with pytest.raises(TypeError, match="frames"):
            module([[0.0, 1.0]])  # numpy frames are converted (tests/library/test_ingestion.py), other types refused

    def test_inside_compose(self, name):
        frames = sparse_frames(2, 6, 2, H, W, density=0.2)
        module = SHAPE_FACTORIES[name](6, H, W)
        pipeline = et.Compose([et.FrameShift(-1), module])
        params = pipeline.make_params(frames.shape, generator=torch.Generator().manual_seed(0))
        assert torch.equal(pipeline(frames, params=params), module(et.FrameShift(-1)(frames), params=params["1"]))
