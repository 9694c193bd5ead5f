"""The issue-13 transforms never read values back to the host (so on CUDA they queue work
without waiting): each runs on the ``meta`` device, where any read of a value raises. On a
machine with CUDA, the same calls match the CPU and run under sync debug mode ``"error"``."""

from __future__ import annotations

import pytest
import torch

import event_transforms as et

from .checkers import H, W, sparse_frames

MODULES = {
    "RandomAffine": lambda: et.RandomAffine(20.0, translate=(0.1, 0.1), scale=(0.9, 1.1), shear=5.0, p=0.5),
    "RandomTranslate": lambda: et.RandomTranslate(2, p=0.5),
    "RandomCrop": lambda: et.RandomCrop((8, 5)),
    "RandomCropResize": lambda: et.RandomCrop((8, 5), resize=True, p=0.5),
    "CenterCrop": lambda: et.CenterCrop(5),
    "Downsample": lambda: et.Downsample(2, remainder="keep"),
    "RandomFlipPolarity": lambda: et.RandomFlipPolarity(),
    "RandomTimeReversal": lambda: et.RandomTimeReversal(),
    "MergePolarities": lambda: et.MergePolarities(),
    "RandomCropTime": lambda: et.RandomCropTime(3),
    "Cutout": lambda: et.Cutout(3),
    "CutMix": lambda: et.CutMix(p=0.5),
    "MixUp": lambda: et.MixUp(),
    "DropPixel": lambda: et.DropPixel([[1, 1]]),
    "DropHotPixels": lambda: et.DropPixel(rate_hz=100.0),
    "RandomDropPixel": lambda: et.RandomDropPixel(0.3),
    "Denoise": lambda: et.Denoise(),
    # issue 18: the contact axis is computed on the device, never read back
    "RandomStretch": lambda: et.RandomStretch((0.8, 1.25), p=0.5),
    "StretchAtAngle": lambda: et.Stretch(1.2, axis=30.0, center="image"),
}


@pytest.mark.parametrize("name", sorted(MODULES))
def test_no_value_is_read_on_the_host(name):
    # float32 and int32: the 8/16-bit integer sums of Downsample and MergePolarities check
    # for overflow on the host, by design and as documented
    for dtype in (torch.float32, torch.int32):
        frames = torch.zeros(4, 6, 2, H, W, dtype=dtype, device="meta")
        module = MODULES[name]()
        out = module(frames, generator=torch.Generator().manual_seed(0))
        assert out.device.type == "meta"
        assert out.shape == module.output_shape(frames.shape)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
@pytest.mark.parametrize("name", sorted(MODULES))
def test_cuda_matches_cpu_without_synchronising(name):
    frames = sparse_frames(4, 6, 2, H, W, density=0.3)
    module = MODULES[name]()
    params = module.make_params(frames.shape, generator=torch.Generator().manual_seed(0))
    expected = module(frames, params=params)
    on_device = frames.cuda()
    module(on_device, params=params)  # warm-up (kornia import, kernels)
    torch.cuda.synchronize()
    torch.cuda.set_sync_debug_mode("error")
    try:
        out = module(on_device, params=params)
    finally:
        torch.cuda.set_sync_debug_mode("default")
    torch.testing.assert_close(out.cpu(), expected, rtol=1e-4, atol=1e-4)
