"""Per-sample purity cost (issue 19): the random kernels applied with a given tree, B = 32,
T = 36, 2 x 70 x 75 Poisson(0.3) counts, one CPU thread, ``torch.utils.benchmark`` medians.

Run it on the tree before and after a change, alternating, and compare the medians::

    MALLOC_MMAP_THRESHOLD_=1073741824 MALLOC_TRIM_THRESHOLD_=1073741824 \\
        PYTHONPATH=<checkout> python benchmarks/purity_cost.py <label>
"""

from __future__ import annotations

import sys

import torch
import torch.utils.benchmark as benchmark


def main(label: str = "") -> None:
    torch.set_num_threads(1)
    import event_transforms as et

    print(label, et.__file__, torch.__version__)
    frames = torch.poisson(torch.full((32, 36, 2, 70, 75), 0.3), generator=torch.Generator().manual_seed(0))
    modules = {
        "TES exact": et.TemporalEventShift(-2, 0.5),
        "TES binomial": et.TemporalEventShift(-2, 0.5, mode="binomial"),
        "EventDrop(random)": et.RandomEventDrop((0.1, 0.5), methods=("random",)),
        "AddPoissonNoise(0.1-10 Hz)": et.AddPoissonNoise((0.1, 10.0)),
    }
    for name, module in modules.items():
        params = module.make_params(frames.shape, generator=torch.Generator().manual_seed(1))
        timer = benchmark.Timer(
            "module(frames, params=params)", globals={"module": module, "frames": frames, "params": params}, num_threads=1
        )
        result = timer.blocked_autorange(min_run_time=3)
        print(f"{name:28s} median {result.median * 1e3:7.1f} ms  IQR {result.iqr * 1e3:5.1f} ms  n={len(result.times)}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "")
