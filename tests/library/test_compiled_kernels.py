"""The opt-in compiled kernels (``et.set_compiled_kernels`` / ``et.compiled_kernels``): eager by
default, one graph per kernel (``fullgraph=True``: a graph break is an error), one compile for
batches of different event counts, and results equal to eager (bit for bit for binning, a stated
float tolerance for the interpolating warp)."""

from __future__ import annotations

import pytest
import torch

import event_transforms as et
from event_transforms import _compile

REASON = _compile.unavailable_reason()
needs_compile = pytest.mark.skipif(REASON is not None, reason=f"torch.compile unavailable here: {REASON}")


def _streams(count: int, n: int, seed: int) -> list[torch.Tensor]:
    """Unsorted-free random streams (x, y, t, p) on a 13 x 17 sensor over 6 ms, a few off the sensor."""
    g = torch.Generator().manual_seed(seed)
    out = []
    for _ in range(count):
        t = torch.sort(torch.randint(0, 6_500, (n,), generator=g)).values  # some past the 6-bin window
        x = torch.randint(-1, 18, (n,), generator=g)  # -1 and 17 lie off the sensor
        y = torch.randint(0, 13, (n,), generator=g)
        p = torch.randint(0, 2, (n,), generator=g)
        out.append(torch.stack([x, y, t, p], 1))
    return out


def _batch(count: int, n: int, seed: int) -> et.EventBatch:
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the streams hold events off the sensor on purpose
        return et.EventBatch.from_streams(_streams(count, n, seed), sensor_size=(13, 17), frame_ms=1.0, t_start=0,
                                          n_frames=6)


def test_eager_is_the_default_and_the_switch_is_checked():
    assert et.compiled_kernels_enabled() is False
    with pytest.raises(TypeError, match="enabled must be a bool, got 1"):
        et.set_compiled_kernels(1)  # type: ignore[arg-type]


def test_unavailable_compile_is_refused_by_reason(monkeypatch):
    monkeypatch.setattr(_compile, "unavailable_reason", lambda: "no C++ compiler")
    with pytest.raises(RuntimeError, match="compiled kernels are unavailable: no C\\+\\+ compiler"):
        et.set_compiled_kernels(True)
    assert et.compiled_kernels_enabled() is False


def test_context_manager_restores_the_setting(monkeypatch):
    monkeypatch.setattr(_compile, "unavailable_reason", lambda: None)
    with et.compiled_kernels():
        assert et.compiled_kernels_enabled()
        with et.compiled_kernels(False):
            assert not et.compiled_kernels_enabled()
        assert et.compiled_kernels_enabled()
    assert not et.compiled_kernels_enabled()


def test_compilable_runs_eager_when_off():
    calls = []

    @_compile.compilable
    def double(x: torch.Tensor) -> torch.Tensor:
        calls.append(1)
        return x * 2

    assert torch.equal(double(torch.arange(3)), torch.tensor([0, 2, 4])) and calls == [1]


@needs_compile
@pytest.mark.slow
def test_batch_binning_compiled_equals_eager_bit_for_bit_with_one_compile():
    """Two batches of different event counts (and batch sizes): one graph, counts and the
    lost-event tallies identical to the eager per-sample path, crop and pool included."""
    from torch._dynamo.utils import counters

    torch._dynamo.reset()
    to_frames = et.EventsToFrames((13, 17), frame_ms=1.0, n_frames=6, crop=(1, 2, 10, 12), pool=2)
    first, second = _batch(3, 500, 0), _batch(5, 321, 1)
    with et.count_dropped() as dropped:
        expected = [to_frames(first), to_frames(second)]
    before = counters["stats"]["unique_graphs"]
    with et.compiled_kernels(), et.count_dropped() as dropped_compiled:
        got = [to_frames(first), to_frames(second)]
    assert counters["stats"]["unique_graphs"] - before == 1  # one compile for both event counts
    for e, g in zip(expected, got):
        assert g.dtype == e.dtype and torch.equal(g, e)
    assert dropped_compiled.counts() == dropped.counts() and dropped.counts()["off_sensor"] > 0


@needs_compile
@pytest.mark.slow
def test_affine_warp_compiled_matches_eager_within_tolerance():
    """Rotation of frames: inductor's grid_sample orders the bilinear sums differently
    (float32 rounding), so equal to eager within 1e-4 of counts of a few events."""
    frames = torch.poisson(torch.full((3, 4, 2, 9, 11), 0.7), generator=torch.Generator().manual_seed(2))
    rotation = et.RandomRotation(30.0)
    params = rotation.make_params(frames.shape, generator=torch.Generator().manual_seed(0))
    expected = rotation(frames, params=params)
    with et.compiled_kernels():
        got = rotation(frames, params=params)
    torch.testing.assert_close(got, expected, atol=1e-4, rtol=1e-5)
