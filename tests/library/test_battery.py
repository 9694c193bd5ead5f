"""The shared battery every module runs: hard cases, dtype/device rules, no in-place change,
reproducibility, pickling, and interop (DataLoader workers, nn.Sequential, torchvision v2,
tv_tensors.Video, tonic-style frames)."""

from __future__ import annotations

import pickle
import warnings

import numpy as np
import pytest
import torch
from torch import nn
from torch.utils.data import DataLoader, Dataset

import event_transforms as et
from event_transforms import functional as F
from event_transforms.transforms._tree import check_tree
from event_transforms.transforms.base import slice_params

from tests.support.topics import collect
from tests.support.checkers import H, W, check_not_modified, check_pickle, check_sane, sparse_frames

INTERPOLATING = {"Rotate", "RandomRotation", "Resize", "RandomResize"}
INTERPOLATING |= {"Affine", "RandomAffine", "RandomCropResize", "CenterCropResize", "RandomPerspective", "RandomElastic"}
INTERPOLATING |= {"Stretch", "StretchAtAngle", "RandomStretch", "StretchToTarget"}
# modules whose kernels need whole, non-negative counts and check them
VALUE_CHECKED = {"TemporalEventShift", "TemporalEventShiftBinomial", "RandomTemporalEventShift", "RandomEventDrop"}


# name -> factory(T, H, W) -> module
# name -> factory: each topic test file holds its own entries (BATTERY in test_<topic>.py)
FACTORIES = collect("BATTERY")
COUPLED = {"CutMix", "MixUp"}

NAMES = sorted(FACTORIES)


def expected_dtype(name: str, dtype: torch.dtype) -> torch.dtype:
    interpolates = name in INTERPOLATING or name in ("Compose", "OneOf", "MixUp")
    if interpolates and not dtype.is_floating_point:
        return torch.float32
    return dtype


def bound(name: str) -> float:
    """Largest factor by which a transform may grow the total count (interpolation)."""
    return 2.5 if name in INTERPOLATING or name in ("Compose", "OneOf", "MixUp") else 1.0 + 1e-6


def run(name: str, frames: torch.Tensor, seed: int = 0) -> torch.Tensor:
    t, _, h, w = frames.shape[-4:]
    module = FACTORIES[name](t, h, w)
    return module(frames, generator=torch.Generator().manual_seed(seed))


@pytest.mark.parametrize("name", NAMES)
class TestBattery:
    @pytest.mark.parametrize(
        "dtype",
        [torch.float32, torch.float16, torch.bfloat16, torch.float64, torch.uint8, torch.int16, torch.int32, torch.int64],
    )
    def test_dtypes(self, name, dtype):
        frames = sparse_frames(3, 6, 2, H, W, density=0.2, dtype=dtype)
        out = check_not_modified(lambda x: run(name, x), frames)
        check_sane(out, frames, expected_dtype(name, dtype))

    def test_empty_frames(self, name):
        frames = torch.zeros(2, 5, 2, H, W)
        out = run(name, frames)
        check_sane(out, frames)
        if name not in ("AddNoise", "AddPoissonNoise"):
            assert out.sum() == 0

    def test_single_event(self, name):
        frames = torch.zeros(1, 5, 2, H, W, dtype=torch.int32)
        frames[0, 2, 1, 8, 5] = 1
        out = run(name, frames)
        check_sane(out, frames, expected_dtype(name, torch.int32))
        if name not in ("AddNoise", "AddPoissonNoise"):
            # interpolation spreads one event over its neighbours: the total may grow by
            # about scale**2 (1.25**2) plus discretisation, never more than bound(name)
            assert 0 <= float(out.double().sum()) <= bound(name)

    @pytest.mark.parametrize("dtype", [torch.int32, torch.float32, torch.float64])
    def test_one_pixel_with_a_million_counts(self, name, dtype):
        frames = torch.zeros(2, 5, 2, H, W, dtype=dtype)
        frames[:, 2, 0, 8, 5] = 10**6
        out = check_not_modified(lambda x: run(name, x), frames)
        check_sane(out, frames, expected_dtype(name, dtype))
        total = float(out.double().sum())
        assert total <= 2 * 10**6 * bound(name) + (out.numel() * 10 if "Noise" in name else 0)

    def test_zero_batch(self, name):
        frames = torch.zeros(0, 5, 2, H, W, dtype=torch.int16)
        out = run(name, frames)
        assert out.shape == frames.shape and out.dtype == expected_dtype(name, torch.int16)

    @pytest.mark.parametrize("shape", [(3, 1, 2, H, W), (2, 4, 2, 1, W), (2, 4, 2, H, 1), (2, 4, 2, 1, 1), (2, 4, 2, 70, 75)])
    def test_odd_shapes(self, name, shape):
        frames = sparse_frames(*shape, density=0.3)
        out = run(name, frames)
        check_sane(out, frames)

    def test_single_sequence_equals_batch_of_one(self, name):
        frames = sparse_frames(6, 2, H, W, density=0.2)
        single = run(name, frames, seed=5)
        batch = run(name, frames.unsqueeze(0), seed=5)
        assert single.shape == frames.shape
        assert torch.equal(single, batch[0])

    def test_seeded_reproducibility(self, name):
        frames = sparse_frames(4, 6, 2, H, W, density=0.2)
        assert torch.equal(run(name, frames, seed=11), run(name, frames, seed=11))

    def test_pickle(self, name):
        frames = sparse_frames(3, 6, 2, H, W, density=0.2)
        check_pickle(FACTORIES[name](6, H, W), frames)

    def test_bad_rank_and_polarity(self, name):
        module = FACTORIES[name](6, H, W)
        with pytest.raises(ValueError, match=r"got \(6, 3, 17, 11\)"):
            module(torch.zeros(6, 3, H, W))
        with pytest.raises(ValueError, match=r"got \(2, 11\)"):
            module(torch.zeros(2, W))
        with pytest.raises(TypeError, match="frames"):
            module([[0.0, 1.0]])
        # numpy frames (tonic's ToFrame, DiskCachedDataset) are converted once, not refused
        frames = np.random.default_rng(0).poisson(1.0, (6, 2, H, W)).astype(np.float32)
        expected = module(torch.from_numpy(frames.copy()), generator=torch.Generator().manual_seed(0))
        assert torch.equal(module(frames, generator=torch.Generator().manual_seed(0)), expected)

    @pytest.mark.parametrize("bad, message", [(-1.0, "non-negative"), (float("nan"), "finite")])
    def test_negative_and_nan_counts(self, name, bad, message):
        # Kernels whose result depends on whole counts refuse bad values by name; the
        # others move or interpolate values without reading them (no host sync), and
        # never clamp or repair them: the bad value is still in the output.
        module = et.RandomEventDrop(0.3, methods=("random",)) if name == "RandomEventDrop" else FACTORIES[name](6, H, W)
        frames = sparse_frames(2, 6, 2, H, W)
        frames[:, 3, 0, 8, 5] = bad
        generator = torch.Generator().manual_seed(0)
        if name in VALUE_CHECKED:
            with pytest.raises(ValueError, match=message):
                module(frames, generator=generator)
        else:
            out = module(frames, generator=generator).double()
            assert bool(out.isnan().any()) if bad != bad else bool((out < 0).any())


    def test_replay_ignores_the_global_rng(self, name):
        frames = sparse_frames(4, 6, 2, H, W, density=0.2, dtype=torch.int32)
        module = FACTORIES[name](6, H, W)
        params = module.make_params(frames.shape, generator=torch.Generator().manual_seed(1))
        torch.manual_seed(0)
        first = module(frames, params=params)
        torch.manual_seed(12345)
        assert torch.equal(module(frames, params=params), first)
        # the tree is exactly what a seeded call draws and uses
        assert torch.equal(module(frames, generator=torch.Generator().manual_seed(1)), first)

    def test_params_are_a_tree_of_batched_cpu_tensors(self, name):
        module = FACTORIES[name](6, H, W)
        for batch in (0, 1, 5):
            params = module.make_params((batch, 6, 2, H, W), generator=torch.Generator().manual_seed(2))
            leaves = list(_leaves(params))
            assert all(leaf.shape[0] == batch and leaf.device.type == "cpu" for leaf in leaves)

    @pytest.mark.parametrize("dtype", [torch.int16, torch.float32])
    def test_batched_equals_per_sample_given_params(self, name, dtype):
        """Per-sample purity: a sample alone with its slice of the tree equals the sample in
        the batch, exactly, also for kernels with randomness of their own (their streams
        are keyed by the sample's seed). Coupled transforms read other samples by
        declaration: their per-sample law is tested with the labels below."""
        if name in COUPLED:
            pytest.skip("couples_samples: a sample depends on its partner by design")
        frames = sparse_frames(5, 6, 2, H, W, density=0.3, dtype=dtype)
        frames[1, 2, 0, 3, 4] = 40  # a count above the kernels' expansion limit
        module = FACTORIES[name](6, H, W)
        if module.p == 1.0 and name not in ("OneOf", "RandomApply"):
            module.p = 0.7  # the gate gathers sub-batches too
        params = module.make_params(frames.shape, generator=torch.Generator().manual_seed(4))
        batched = module(frames, params=params)
        for b in (0, 1, 4):
            alone = module(frames[b : b + 1], params=slice_params(params, torch.tensor([b])))
            if name in INTERPOLATING or name in ("Compose", "OneOf"):  # bilinear arithmetic may differ in the last bit
                torch.testing.assert_close(alone[0], batched[b], rtol=1e-5, atol=1e-5)
            else:
                assert torch.equal(alone[0], batched[b]), (name, b)
        # and a permuted batch gives each sample the same output
        order = torch.tensor([4, 2, 0, 1, 3])
        permuted = module(frames[order], params=slice_params(params, order))
        torch.testing.assert_close(permuted, batched[order], rtol=1e-5, atol=1e-5)

    def test_metadata_reaches_through_containers(self, name):
        frames = sparse_frames(4, 6, 2, H, W, density=0.2)
        metadata = {"diameter_mm": torch.tensor([12.0, 18.0, 12.0, 18.0])}
        module, probe = FACTORIES[name](6, H, W), _Probe()
        if name in COUPLED:  # containers that hand out sub-batches refuse it by name
            with pytest.raises(TypeError, match=rf"transforms\[0\] \({name}\) mixes samples"):
                et.OneOf([module, probe])
            with pytest.raises(TypeError, match=r"transform \(Compose\) mixes samples"):
                et.RandomApply(et.Compose([probe, module]), p=1.0)
            containers = (et.Compose([module, probe]),)
        else:
            containers = (et.Compose([module, probe]), et.OneOf([module, probe]), et.RandomApply(et.Compose([probe, module]), p=1.0))
        for container in containers:
            probe.seen.clear()
            params = container.make_params(frames.shape, metadata=metadata, generator=torch.Generator().manual_seed(0))
            assert probe.seen and all(seen is metadata for seen in probe.seen)
            out = container(frames, params=params)
            if isinstance(container, et.Compose):  # the module's part of the tree replays it alone
                torch.testing.assert_close(out, module(frames, params=params["0"]))

    def test_p_gates_each_sample(self, name):
        frames = sparse_frames(6, 6, 2, H, W, density=0.2)
        module = FACTORIES[name](6, H, W)
        module.p = 0.5
        params = module.make_params(frames.shape, generator=torch.Generator().manual_seed(6))
        gate = params["apply"]
        assert gate.dtype == torch.bool and gate.shape == (6,) and 0 < int(gate.sum()) < 6
        out = module(frames, params=params)
        chosen = gate.nonzero().squeeze(1)
        if name in COUPLED:  # chosen samples as in the ungated call (partners read unchanged)
            always = FACTORIES[name](6, H, W)
            always.p = 1.0
            ungated = always(frames, params={k: v for k, v in params.items() if k != "apply"})
            assert torch.equal(out[chosen], ungated[chosen].to(out.dtype))
            assert torch.equal(out[~gate], frames[~gate].to(out.dtype))
            return
        # the gated samples are the transform of that sub-batch with its slice of the tree
        own = slice_params({k: v for k, v in params.items() if k != "apply"}, chosen)
        always = FACTORIES[name](6, H, W)
        always.p = 1.0
        assert torch.equal(out[chosen], always(frames[chosen], params=own).to(out.dtype))
        assert torch.equal(out[~gate], frames[~gate].to(out.dtype))
        module.p = 0.0
        assert torch.equal(module(frames).to(frames.dtype), frames)

    def test_gate_read_or_not_gives_the_same_result(self, name, monkeypatch):
        """The one gating rule has two evaluations: gather the kept samples (a CPU gate, read
        on the host) and select over the whole batch (traced calls and accelerator gates,
        which cannot be read); they agree on every module."""
        frames = sparse_frames(6, 6, 2, H, W, density=0.2)
        module = FACTORIES[name](6, H, W)
        module.p = 0.5
        params = module.make_params(frames.shape, generator=torch.Generator().manual_seed(6))
        gathered = module(frames, params=params)
        monkeypatch.setattr(torch.compiler, "is_compiling", lambda: True)
        selected = module(frames, params=params)
        assert selected.dtype == gathered.dtype
        torch.testing.assert_close(selected, gathered, rtol=1e-5, atol=1e-5)

    def test_named_errors_for_bad_params(self, name):
        module = FACTORIES[name](6, H, W)
        frames = sparse_frames(2, 6, 2, H, W)
        with pytest.raises(TypeError, match="params must be a dict"):
            module(frames, params=[1, 2])
        good = module.make_params(frames.shape)
        if good:
            with pytest.raises(ValueError, match=r"params.*has no entry|must have shape \(2, \.\.\.\)"):
                module(frames, params={})
            key, value = next(iter(_items(good)))
            with pytest.raises(ValueError, match=r"[A-Za-z]+: params.*must have shape \(2,"):
                module(frames, params=_replace(good, key, torch.cat([value, value])))
        with pytest.raises(ValueError, match=rf"{type(module).__name__}: params has unknown key\(s\) \['bogus'\]"):
            module(frames, params={**good, "bogus": torch.zeros(2)})
        with pytest.raises(TypeError, match=r"params\['apply'\] must be a bool tensor"):
            module(frames, params={**good, "apply": torch.tensor([0.1, 0.9])})
        with pytest.raises(TypeError, match="generator must be a torch.Generator or None, got int"):
            module(frames, generator=0)
        with pytest.raises(TypeError, match="generator must be a torch.Generator or None, got Generator"):
            module(frames, generator=np.random.default_rng(0))

    def test_params_spec_describes_every_entry(self, name):
        """Every library module describes its params (so replays are checked), and what
        make_params draws fits the description."""
        module = FACTORIES[name](6, H, W)
        module.p = 0.5
        shape = torch.Size((3, 6, 2, H, W))
        good = module.make_params(shape, generator=torch.Generator().manual_seed(8))
        assert module.params_spec(shape) is not None
        checked = check_tree(module, good, shape)
        assert _keys(checked) == _keys(good)


class _Probe(et.EventTransform):
    """Records the metadata its make_params sees; the identity."""

    def __init__(self):
        super().__init__()
        self.seen = []

    def sample_params(self, shape, *, generator=None, metadata=None):
        self.seen.append(metadata)
        return {}

    def params_spec(self, shape):
        return {}

    def apply_transform(self, frames, params):
        return frames


def _items(tree, prefix=()):
    for key, value in tree.items():
        if isinstance(value, dict):
            yield from _items(value, prefix + (key,))
        else:
            yield prefix + (key,), value


def _leaves(tree):
    return (value for _, value in _items(tree))


def _keys(tree):
    return {path[-1] for path, _ in _items(tree)}


def _replace(tree, path, value):
    out = dict(tree)
    out[path[0]] = value if len(path) == 1 else _replace(tree[path[0]], path[1:], value)
    return out


# ----------------------------------------------------------------------------- interop


class _Sequences(Dataset):
    def __init__(self, transform):
        self.frames = sparse_frames(8, 6, 2, H, W, density=0.3)
        self.transform = transform

    def __len__(self):
        return 8

    def __getitem__(self, index):
        return self.transform(self.frames[0])  # the same sequence every time


def test_dataloader_workers_draw_differently():
    loader = DataLoader(_Sequences(et.RandomRotation(180.0)), batch_size=4, num_workers=2)
    first, second = list(loader)
    assert not torch.equal(first[0], second[0])  # worker 0 and worker 1
    assert not torch.equal(first[0], first[1])  # consecutive draws in one worker


def test_collated_batch_gets_per_sample_parameters():
    batch = sparse_frames(1, 6, 2, H, W, density=0.3).expand(8, 6, 2, H, W)
    out = et.RandomRotation(180.0)(batch, generator=torch.Generator().manual_seed(0))
    assert len({tuple(o.flatten()[:50].tolist()) for o in out}) == 8


def test_inside_nn_sequential():
    frames = sparse_frames(2, 6, 2, H, W, density=0.3)
    model = nn.Sequential(et.FrameShift(-1), et.Rotate(15.0))
    torch.testing.assert_close(model(frames), et.Rotate(15.0)(et.FrameShift(-1)(frames)))


def test_inside_torchvision_v2_compose_keeps_video():
    from torchvision import tv_tensors
    from torchvision.transforms import v2

    video = tv_tensors.Video(sparse_frames(6, 2, H, W, density=0.3))
    pipeline = v2.Compose([et.Rotate(20.0), et.FrameShift(1), v2.ToDtype(torch.float64)])
    out = pipeline(video)
    assert isinstance(out, tv_tensors.Video)
    assert out.dtype == torch.float64
    expected = et.FrameShift(1)(et.Rotate(20.0)(video.as_subclass(torch.Tensor))).double()
    torch.testing.assert_close(out.as_subclass(torch.Tensor), expected)


@pytest.mark.parametrize("name", ["RandomRotation", "RandomTemporalEventShift", "OneOf"])
def test_video_in_video_out(name):
    from torchvision import tv_tensors

    video = tv_tensors.Video(sparse_frames(2, 6, 2, H, W, density=0.3))
    out = FACTORIES[name](6, H, W)(video)
    assert isinstance(out, tv_tensors.Video)


def test_tonic_to_frame_output_accepted_as_is():
    # tonic's ToFrame returns an int16 numpy array (T, P, H, W), polarity 0 = OFF
    frames = torch.from_numpy(np.random.default_rng(0).poisson(0.1, (36, 2, 70, 75)).astype(np.int16))
    out = et.TemporalEventShift(-2, 0.5)(frames, generator=torch.Generator().manual_seed(0))
    assert out.dtype == torch.int16 and out.shape == (36, 2, 70, 75)


def test_modules_are_picklable_for_spawned_workers():
    for name in NAMES:
        module = FACTORIES[name](6, H, W)
        assert repr(pickle.loads(pickle.dumps(module))) == repr(module)


def test_torchvision_v2_passes_other_inputs_through():
    from torchvision import tv_tensors
    from torchvision.transforms import v2

    frames = sparse_frames(3, 6, 2, H, W, density=0.3)
    label = torch.arange(3.0)
    pipeline = v2.Compose([et.RandomRotation(20.0), et.FrameShift(-1)])
    torch.manual_seed(0)
    out, same_label = pipeline(frames, label)
    assert same_label is label
    torch.manual_seed(0)
    assert torch.equal(out, et.FrameShift(-1)(et.RandomRotation(20.0)(frames)))
    # a Video among other inputs stays a Video
    video, extra = et.FrameShift(1)(tv_tensors.Video(frames), {"force": label})
    assert isinstance(video, tv_tensors.Video) and extra == {"force": label}


def test_dict_samples_keep_their_other_entries():
    frames = sparse_frames(2, 6, 2, H, W, density=0.3)
    sample = {"frames": frames, "force": torch.ones(2, 6), "diameter_mm": torch.tensor([12.0, 18.0])}
    out = et.Compose([et.FrameShift(-1), et.ResizeToTarget(15.0)])(sample)
    assert set(out) == set(sample) and out["force"] is sample["force"]
    expected = et.Resize(1.0)(et.FrameShift(-1)(frames))  # shapes and dtype
    assert out["frames"].shape == expected.shape
    with pytest.raises(ValueError, match="'frames'"):
        et.FrameShift(1)({"events": frames})


@pytest.mark.parametrize(
    "build",
    [
        lambda n: et.Rotate(n(30.0)),
        lambda n: et.RandomRotation(n(30.0)),
        lambda n: et.RandomRotation((n(-10.0), n(10.0))),
        lambda n: et.Resize(n(1.25)),
        lambda n: et.RandomResize((n(0.8), n(1.2))),
        lambda n: et.RandomResize(choices=(n(0.8), n(1.25))),
        lambda n: et.FrameShift(n(-1)),
        lambda n: et.RandomFrameShift((n(-1), n(1))),
        lambda n: et.TemporalEventShift(n(-2), n(0.5)),
        lambda n: et.RandomTemporalEventShift((n(-2),), (n(0.2), n(0.8))),
        lambda n: et.AddPoissonNoise(n(5.0), frame_ms=n(10.0)),
        lambda n: et.RandomEventDrop(n(0.3)),
        lambda n: et.RandomHorizontalFlip(n(0.5)),
        lambda n: et.OneOf([et.FrameShift(1), et.FrameShift(-1)], weights=[n(1.0), n(2.0)]),
        lambda n: et.RandomApply(et.FrameShift(1), p=n(0.5)),
        lambda n: et.ResizeToTarget(n(15.0), exponent=n(0.5)),
    ],
)
@pytest.mark.parametrize("kind", ["numpy", "tensor"])
def test_numpy_scalars_and_zero_dim_tensors_are_numbers(build, kind):
    def number(value):
        if kind == "numpy":
            return np.int64(value) if isinstance(value, int) else np.float64(value)
        return torch.tensor(value, dtype=torch.int64 if isinstance(value, int) else torch.float64)

    reference = build(lambda value: value)
    module = build(number)
    assert repr(module) == repr(reference)
    frames = sparse_frames(2, 6, 2, H, W, density=0.3)
    meta = {"diameter_mm": [12.0, 18.0]}
    out = module(frames, generator=torch.Generator().manual_seed(0), metadata=meta)
    torch.testing.assert_close(out, reference(frames, generator=torch.Generator().manual_seed(0), metadata=meta))


def test_issue_examples_of_numbers():
    frames = sparse_frames(2, 6, 2, H, W, density=0.3, dtype=torch.int64)
    g = lambda: torch.Generator().manual_seed(0)  # noqa: E731
    assert torch.equal(
        et.TemporalEventShift(-1, fraction=np.float32(0.5))(frames, generator=g()),
        et.TemporalEventShift(-1, fraction=0.5)(frames, generator=g()),
    )
    assert torch.equal(et.Rotate(torch.tensor(30.0))(frames), et.Rotate(30.0)(frames))


def test_unsigned_wide_dtypes_are_refused_by_name():
    for dtype in (torch.uint16, torch.uint32, torch.uint64):
        with pytest.raises(TypeError, match=f"got {dtype}"):
            et.FrameShift(1)(torch.zeros(2, 2, 3, 3, dtype=dtype))


class TestRawAndSilentCases:
    """The bad-input battery's raw and silent cases (issue 27), each with its named outcome."""

    def test_value_reading_transform_on_meta_frames(self):
        frames = torch.zeros(2, 3, 2, 8, 8, device="meta")
        with pytest.raises(ValueError, match="RandomTemporalEventShift reads the values .* device 'meta'"):
            et.RandomTemporalEventShift([-1, 1])(frames)
        with pytest.raises(ValueError, match="Compose reads the values"):
            et.Compose([et.RandomRotation(10), et.RandomTemporalEventShift([-1, 1])])(frames)
        assert et.RandomRotation(10)(frames).device.type == "meta"  # shape-only transforms still run there

    def test_params_tree_on_meta(self):
        module = et.Compose([et.RandomRotation(10), et.RandomTemporalEventShift([-1, 1])])
        params = module.make_params((2, 3, 2, 8, 8), generator=torch.Generator().manual_seed(0))
        params["1"] = {k: v.to("meta") for k, v in params["1"].items()}
        with pytest.raises(ValueError, match=r"params\['1'\]\['\w+'\] is on the meta device"):
            module(torch.zeros(2, 3, 2, 8, 8), params=params)

    @pytest.mark.parametrize("generator", [5, "seed", np.random.default_rng(0)])
    def test_make_params_generator_of_the_wrong_type(self, generator):
        with pytest.raises(TypeError, match="make_params: generator must be a torch.Generator or None, got"):
            et.RandomRotation(10).make_params((2, 3, 2, 8, 8), generator=generator)

    def test_meta_generator_is_refused_by_torch_itself(self):
        # torch's own constructor raises before any library code runs: documented, not ours to change
        with pytest.raises(RuntimeError, match="META"):
            torch.Generator(device="meta")

    @pytest.mark.parametrize("module", [et.Downsample(2), et.MergePolarities()], ids=["Downsample", "MergePolarities"])
    @pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16])
    def test_half_precision_overflow_is_refused_by_name(self, module, dtype):
        frames = torch.full((1, 2, 2, 4, 4), torch.finfo(dtype).max * 0.75, dtype=dtype)
        with pytest.raises(ValueError, match=rf"does not fit frames of dtype {dtype}"):
            module(frames)
        small = torch.ones(1, 2, 2, 4, 4, dtype=dtype)
        assert torch.isfinite(module(small)).all()

    @pytest.mark.parametrize("name, module", [
        ("RandomRotation", lambda: et.RandomRotation(20)),
        ("RandomResize", lambda: et.RandomResize((0.8, 1.2))),
        ("RandomAffine", lambda: et.RandomAffine(20)),
        ("RandomStretch", lambda: et.RandomStretch((0.8, 1.25))),
        ("RandomPerspective", lambda: et.RandomPerspective(0.3)),
        ("RandomElastic", lambda: et.RandomElastic(alpha=(2.0, 6.0), sigma=2.0)),
    ])
    def test_nan_pixel_stays_local(self, name, module):
        # NaN policy of the interpolating kernels: a NaN pixel reaches only the output pixels
        # whose interpolation reads it; it never moves a sample's centre of mass
        frames = torch.rand(2, 3, 2, 16, 16)
        frames[0, 1, 0, 8, 8] = float("nan")
        out = module()(frames, generator=torch.Generator().manual_seed(0))
        nan = out.isnan()
        assert nan[0, 1, 0].sum() <= 16, f"{name}: {int(nan[0, 1, 0].sum())} NaN pixels from one"
        assert nan.sum() == nan[0, 1, 0].sum()  # no other frame, polarity or sample touched
        clean = frames.clone()
        clean[0, 1, 0, 8, 8] = 0.0
        expected = module()(clean, generator=torch.Generator().manual_seed(0))
        assert torch.equal(out[1], expected[1])  # the other sample is as without the NaN

    def test_center_of_mass_ignores_non_finite_pixels(self):
        from event_transforms.functional._warp import center_of_mass

        frames = torch.zeros(3, 2, 5, 7)
        frames[0, 1, 1, 2] = 1.0
        with_nan = frames.clone()
        with_nan[2, 0, 4, 6] = float("nan")
        with_nan[1, 0, 0, 0] = float("inf")
        assert torch.equal(center_of_mass(with_nan), center_of_mass(frames))

    def test_augmented_dataset_base_checked_at_construction(self):
        with pytest.raises(TypeError, match="base must be a map-style data set .* got int 5"):
            et.AugmentedDataset(5, et.HorizontalFlip())


def _dvxplorer(n: int = 4000, seed: int = 0, span_us: int = 590_000) -> dict[str, np.ndarray]:
    """A 240×320 DVXplorer-like stream with absolute microsecond timestamps (as tonic reads them)."""
    rng = np.random.default_rng(seed)
    return {"x": rng.integers(0, 320, n), "y": rng.integers(0, 240, n),
            "t": 1_600_000_000_000_000 + np.sort(rng.integers(0, span_us, n)), "p": rng.integers(0, 2, n)}


def _with_t(events: dict[str, np.ndarray], t: np.ndarray) -> dict[str, np.ndarray]:
    return {**events, "t": t}


class TestUnitsAndWindows:
    """The bad-input battery's unit and window cases (issue 44): a timestamp span, ``frame_ms``,
    sensor size or window that only makes sense in another unit or order is refused, or warned
    about with the numbers and the fix; never binned silently."""

    def test_epoch_nanoseconds_without_a_unit_are_refused(self):
        events = _dvxplorer()
        ns = _with_t(events, events["t"] * 1000)
        with pytest.raises(ValueError, match=r"as microseconds since the epoch is the year .*Pass time_unit='ns'"):
            F.events_to_frames(ns, sensor_size=(240, 320), n_frames=36)
        assert torch.equal(F.events_to_frames(ns, sensor_size=(240, 320), n_frames=59, time_unit="ns"),
                           F.events_to_frames(events, sensor_size=(240, 320), n_frames=59))

    def test_relative_nanoseconds_in_a_window_warn_with_the_unit(self):
        events = _dvxplorer()
        ns = _with_t(events, (events["t"] - events["t"][0]) * 1000)
        with pytest.warns(et.events.EventsOutsideWindowWarning, match=r"0\.06\d? % of the events' span.*time_unit"):
            F.events_to_frames(ns, sensor_size=(240, 320), n_frames=36)

    def test_float_seconds_under_time_unit_us_are_refused(self):
        events = _dvxplorer()
        seconds = _with_t(events, (events["t"] - events["t"][0]) / 1e6)
        with pytest.raises(ValueError, match=r"under time_unit='us': 4,000 events span 0\.5\d+ us .* look like seconds"):
            F.events_to_frames(seconds, sensor_size=(240, 320), time_unit="us")
        assert F.events_to_frames(seconds, sensor_size=(240, 320), time_unit="s").shape[0] == 59

    def test_frame_ms_in_seconds_names_frame_ms(self):
        with pytest.raises(ValueError, match=r"frame_ms is in milliseconds: frame_ms=0\.01 makes bins of 10 µs "
                                             r"\(if 0\.01 s was meant, pass frame_ms=10\)"):
            F.events_to_frames(_dvxplorer(), sensor_size=(240, 320), frame_ms=0.01)

    def test_no_sensor_size_is_required_as_by_the_module(self):
        with pytest.raises(TypeError, match=r"events_to_frames needs sensor_size=\(H, W\)"):
            F.events_to_frames(_dvxplorer())
        with pytest.raises(TypeError, match=r"EventsToFrames needs sensor_size=\(H, W\)"):
            et.EventsToFrames()

    def test_w_first_sensor_size_names_the_swap(self):
        with pytest.warns(et.events.EventsOutsideSensorWarning) as record:
            F.events_to_frames(_dvxplorer(), sensor_size=(320, 240))
        w = record[0].message
        assert w.swapped and w.suggested_sensor_size == (240, 320)
        assert "sensor_size is (H, W), height first: a sensor 320 wide and 240 high is sensor_size=(240, 320)" in str(w)
        assert f"{w.dropped:,} of 4,000 events" in str(w)

    def test_rows_with_x_and_y_swapped_name_the_swap(self):
        events = _dvxplorer()
        rows = np.stack([events["y"], events["x"], events["t"], events["p"]], 1)
        with pytest.warns(et.events.EventsOutsideSensorWarning) as record:
            F.events_to_frames(rows, sensor_size=(240, 320))
        w = record[0].message
        assert w.swapped and "with x and y exchanged: if the rows are (y, x, t, p), pass columns='yxtp'" in str(w)
        assert torch.equal(F.events_to_frames(rows, sensor_size=(240, 320), columns="yxtp"),
                           F.events_to_frames(events, sensor_size=(240, 320)))

    def test_a_stream_past_its_declared_window_warns_where_the_batch_is_built(self):
        rng = np.random.default_rng(1)
        n = 5000
        stream = torch.from_numpy(np.stack([rng.integers(0, 320, n), rng.integers(0, 240, n),
                                            np.sort(rng.integers(0, 920_000, n)), rng.integers(0, 2, n)], 1))
        with pytest.warns(et.events.EventsOutsideWindowWarning) as record:
            batch = et.EventBatch.from_streams([stream], sensor_size=(240, 320), frame_ms=10.0, n_frames=36, t_start=0)
        w = record[0].message
        outside = int((stream[:, 2] >= 360_000).sum())
        assert (w.dropped, w.total, w.per_stream) == (outside, n, [(outside, n)]) and record[0].filename == __file__
        assert f"{outside:,} of 5,000 events" in str(w) and "EventBatch.from_streams(t_start=0, n_frames=36" in str(w)
        assert int(F.bin_events(batch).sum()) == n - outside
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # a window that holds the streams: no warning
            et.EventBatch.from_streams([stream], sensor_size=(240, 320), frame_ms=10.0, n_frames=92, t_start=0)

    def test_collate_unequal_force_lengths_names_the_items(self):
        events = np.zeros(3, dtype=[("x", "<i2"), ("y", "<i2"), ("t", "<i8"), ("p", "<i1")])
        items = [(events, torch.zeros(35)), (events, torch.zeros(36)), (events, torch.zeros(35))]
        with pytest.raises(ValueError, match=r"most are \(35,\), but item 1: \(36,\) \(lengths \[35, 36\]\)"):
            F.collate_events(items, sensor_size=(4, 4))

    def test_collate_dict_items_says_what_to_pass(self):
        events = np.zeros(3, dtype=[("x", "<i2"), ("y", "<i2"), ("t", "<i8"), ("p", "<i1")])
        with pytest.raises(TypeError, match=r"dict with keys \['events', 'force'\].*Return \(item\['events'\], "
                                            r"item\['force'\]\)"):
            F.collate_events([{"events": events, "force": torch.zeros(3)}], sensor_size=(4, 4))

    def test_iter_frames_of_a_whole_structured_array(self):
        events = np.zeros(3, dtype=[("x", "<i2"), ("y", "<i2"), ("t", "<i8"), ("p", "<i1")])
        with pytest.raises(TypeError, match=r"iter_frames takes an iterable of event chunks, got a numpy structured "
                                            r"array \(one whole stream\): pass \[events\]"):
            F.iter_frames(events, sensor_size=(4, 4))
        assert len(list(F.iter_frames([events], sensor_size=(4, 4)))) == 1
