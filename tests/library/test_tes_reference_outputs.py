"""Exact TES pinned bit for bit: the outputs of exact temporal event shifting on
frames and on an EventBatch (then binned), for fixed seeds, are the ones the implementation gave
before it was made faster (commit 59ec9f2), held here as SHA-256 digests of the output's dtype,
shape and bytes. Cases: grasp-like sparse frames (the binomial level runs), dense Poisson counts,
counts above the expansion limit, uint8 and int16 counts near their limits, float16 and
bfloat16, T = 1, B = 0, shifts longer than the sequence, per-sample shifts and fractions with
ζ = 0 and 1, and the conserved counts are checked alongside."""

from __future__ import annotations

import hashlib

import pytest
import torch

import event_transforms as et
from event_transforms._profiling import synthetic_frames
from event_transforms.functional import bin_events

from tests.support.event_data import SENSOR, T, make_streams


def digest(x: torch.Tensor) -> str:
    data = x.contiguous()
    if data.dtype in (torch.bfloat16, torch.float16):
        data = data.view(torch.int16)
    blob = f"{x.dtype}{tuple(x.shape)}".encode() + data.numpy().tobytes()
    return hashlib.sha256(blob).hexdigest()[:24]


def _poisson(shape, lam, seed):
    return torch.poisson(torch.full(shape, lam), generator=torch.Generator().manual_seed(seed))


def _near(dtype, high, shape=(2, 5, 2, 6, 7), seed=0):
    """Counts in [high - 3, high] on a third of the pixels, zero elsewhere."""
    g = torch.Generator().manual_seed(seed)
    values = torch.randint(high - 3, high + 1, shape, generator=g)
    return torch.where(torch.rand(shape, generator=g) < 0.35, values, 0).to(dtype)


# name -> (frames factory, shift, fraction)
FRAME_CASES = {
    "grasp-like": (lambda: synthetic_frames((3, 36, 2, 70, 75), seed=0), -2, 0.5),
    "poisson dense": (lambda: _poisson((2, 8, 2, 20, 24), 1.5, 1).to(torch.int64), 1, 0.3),
    "counts to ~20": (lambda: synthetic_frames((2, 12, 2, 30, 32), mean_count=8.0, seed=2), -1, 0.7),
    "uint8 near 127": (lambda: _near(torch.uint8, 127), -1, 0.5),
    "uint8 near 140": (lambda: _near(torch.uint8, 140, seed=9), 1, 0.5),
    "int16 near 16383": (lambda: _near(torch.int16, 16383), 2, 0.4),
    "float16": (lambda: _poisson((2, 6, 2, 9, 11), 3.0, 3).to(torch.float16), -1, 0.5),
    "bfloat16": (lambda: _poisson((2, 6, 2, 9, 11), 2.0, 4).to(torch.bfloat16), 1, 0.25),
    "T = 1": (lambda: _poisson((3, 1, 2, 9, 11), 2.0, 5), -1, 0.5),
    "B = 0": (lambda: torch.zeros(0, 6, 2, 9, 11), -2, 0.5),
    "shift past the end": (lambda: _poisson((2, 6, 2, 9, 11), 2.0, 6), 40, 0.6),
    "per-sample": (lambda: _poisson((4, 7, 2, 10, 12), 4.0, 7),
                   torch.tensor([-3, 0, 2, -1]), torch.tensor([0.0, 0.5, 1.0, 0.35])),
    "wide rows": (lambda: _poisson((1, 4, 2, 60, 64), 6.0, 8), -1, 0.45),
}

EXPECTED_FRAMES = {
    'B = 0': 'd7c8bc8a6e3707f98b6c1040',
    'T = 1': 'ab01fb45f3ac839f8b54c6c8',
    'bfloat16': '371e1a23640b2abe01735ad4',
    'counts to ~20': 'f0cddfc20f18690d3f276c44',
    'float16': '1822c79ab1d7fb8b50dc2fd0',
    'grasp-like': '26272502413ac6d9d2962319',
    'int16 near 16383': 'd2659eb249869f0211f34fa2',
    'per-sample': '75e25e65ec981202fa6c93ce',
    'poisson dense': 'feeac8e8ff8d42b505e98cbb',
    'shift past the end': '7a0cb222ef4ad005ea8fd116',
    'uint8 near 127': '789cdca05e65058445d49e40',
    'uint8 near 140': 'f4e437299230a6789d61b206',
    'wide rows': 'c39c121e6ba9c44d3c12b246',
}


def _frames_case(name):
    make, shift, fraction = FRAME_CASES[name]
    frames = make()
    out = et.functional.temporal_event_shift(frames, shift, fraction, generator=torch.Generator().manual_seed(11))
    return frames, out


@pytest.mark.parametrize("name", sorted(FRAME_CASES))
def test_exact_tes_on_frames_is_pinned(name):
    frames, out = _frames_case(name)
    assert out.dtype == frames.dtype and out.shape == frames.shape
    assert digest(out) == EXPECTED_FRAMES[name]


@pytest.mark.parametrize("name", ["grasp-like", "poisson dense", "counts to ~20", "per-sample", "wide rows", "T = 1",
                                  "shift past the end", "uint8 near 140"])
def test_exact_tes_moves_round_zeta_n_of_every_row(name):
    """Row (frame t, polarity) keeps N_t - k_t and receives k_{t-j}, k = round(ζ N) exactly."""
    make, shift, fraction = FRAME_CASES[name]
    frames, out = _frames_case(name)
    b, t = frames.shape[:2]
    shifts = torch.as_tensor(shift).expand(b).tolist()
    zetas = torch.as_tensor(fraction, dtype=torch.float64).expand(b)
    n = frames.double().sum(dim=(3, 4))  # (B, T, 2)
    k = torch.round(zetas.view(b, 1, 1) * n)
    expected = n - k
    for i, j in enumerate(shifts):
        if abs(j) < t:
            src = k[i, max(0, -j) : t - max(0, j)]
            expected[i, max(0, j) : t - max(0, -j)] += src
    assert torch.equal(out.double().sum(dim=(3, 4)), expected)


def test_exact_tes_keeps_the_total_when_nothing_leaves():
    frames = _poisson((3, 6, 2, 9, 11), 2.0, 9)
    frames[:, :2] = 0  # shift -2 moves nothing out of the sequence
    out = et.functional.temporal_event_shift(frames, -2, 0.5, generator=torch.Generator().manual_seed(0))
    assert torch.equal(out.sum(dim=(1, 3, 4)), frames.sum(dim=(1, 3, 4)))


def test_a_result_past_the_dtype_raises():
    frames = _near(torch.int16, 32760, seed=1)
    with pytest.raises(ValueError, match="more than torch.int16 holds exactly"):
        et.functional.temporal_event_shift(frames, -1, 0.9, generator=torch.Generator().manual_seed(0))


def test_exact_tes_module_replays_pinned_draws():
    frames = synthetic_frames((4, 36, 2, 70, 75), seed=3)
    module = et.RandomTemporalEventShift((-2, -1), (0.3, 0.7))
    params = module.make_params(frames.shape, generator=torch.Generator().manual_seed(5))
    whole = module(frames, params=params)
    assert digest(whole) == EXPECTED_MODULE
    from event_transforms.transforms.base import slice_params

    alone = module(frames[2:3], params=slice_params(params, torch.tensor([2])))
    assert torch.equal(alone[0], whole[2])


EXPECTED_MODULE = '4d2941301012a907c45f9a62'


def _events(seed, n=None):
    streams = make_streams(5, seed=seed, n=n)
    streams[3] = streams[3][:0]
    return et.EventBatch.from_streams(streams, sensor_size=SENSOR, frame_ms=1.0, t_start=0, n_frames=T)


EVENT_CASES = {
    "streams": (lambda: _events(1), torch.tensor([-2, -1, 1, 2, 0]), torch.tensor([0.5, 0.3, 0.7, 1.0, 0.0])),
    "dense streams": (lambda: _events(2, n=3000), -1, 0.5),
    "shift past the end": (lambda: _events(3), 9, 0.6),
}

EXPECTED_EVENTS = {
    'dense streams': ['585aa0833f52dd13757805b2', 'da5b52532f7734afcbe84e7f'],
    'shift past the end': ['ee86cbf070fd6246a43252aa', 'dee96de5b38d08d318bde287'],
    'streams': ['1a048816f22d29393e238b3d', '4c39993d33526d3b27fef25e'],
}


@pytest.mark.parametrize("name", sorted(EVENT_CASES))
def test_exact_tes_on_events_and_binned_is_pinned(name):
    make, shift, fraction = EVENT_CASES[name]
    batch = make()
    out = et.functional.temporal_event_shift(batch, shift, fraction, generator=torch.Generator().manual_seed(12))
    columns = torch.cat([out.x.long(), out.y.long(), out.t.long(), out.p.long(), out.offsets])
    assert [digest(columns), digest(bin_events(out))] == EXPECTED_EVENTS[name]
