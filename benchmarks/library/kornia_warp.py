"""The library's own affine warp against kornia's, and the cost of the kornia warps it uses.

Issue 19 asks whether kornia earns its place as a hard dependency. On the paper's batch
(32, 36, 2, 70, 75) float32, with the same per-sample parameters drawn once outside the
timed calls, each row is one call; for each it reports the top-level aten ops dispatched
(``torch.profiler``, see ``event_transforms._profiling.count_ops``), the host synchronisations, and
the CPU time (median and IQR of ``torch.utils.benchmark`` blocks, interleaved rounds) as a
multiple of ``frames.clone()`` and of the own warp timed in the same rounds:

- rotation about the event centroid: ``event_transforms.functional.rotate`` against
  ``kornia.geometry.transform.warp_affine`` with ``get_rotation_matrix2d`` about the same
  centroid (T·2 frames folded into channels, as the own warp does);
- rotation about the image centre: ``rotate(center="image")`` against
  ``kornia.augmentation.VideoSequential(RandomRotation, same_on_frame=True)``, the way a
  kornia user rotates sequences (it has no centroid);
- resize (zoom about the centroid): ``resize`` against ``warp_affine`` with a scale matrix;
- the warps the library takes from kornia: ``perspective`` (``warp_perspective``) and
  ``elastic`` (``elastic_transform2d``), against the own affine warp.

Run: ``MALLOC_MMAP_THRESHOLD_=1073741824 MALLOC_TRIM_THRESHOLD_=1073741824 python
benchmarks/library/kornia_warp.py --threads 1`` (``--quick`` for a smoke run).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import torch

from benchmarks._common import (
    allocator_suffix, apply_threads, base_parser, command, count_ops, environment_lines, fmt_ms, fmt_ratio,
    markdown_table, publish, synthetic_frames, time_interleaved,
)

import event_transforms as et
from event_transforms import functional as F

__all__ = ["build_cases", "PAIRS", "run", "main"]

SHAPE = (32, 36, 2, 70, 75)
QUICK_SHAPE = (4, 6, 2, 17, 11)
BASELINE = "frames.clone() (baseline)"
# kornia row -> the own row it is compared with
PAIRS = {
    "kornia warp_affine + get_rotation_matrix2d (centroid)": "own RandomRotation (centroid)",
    "kornia.augmentation VideoSequential(RandomRotation) (image centre)": "own RandomRotation (image centre)",
    "kornia warp_affine, scale matrix (centroid)": "own RandomResize (centroid)",
    "kornia get_perspective_transform + warp_perspective": "own RandomPerspective",
    "kornia.augmentation VideoSequential(RandomPerspective)": "own RandomPerspective",
    "kornia elastic_transform2d": "own RandomElastic",
    "kornia.augmentation VideoSequential(RandomElasticTransform)": "own RandomElastic",
}


def build_cases(frames: torch.Tensor, seed: int = 0) -> tuple[dict[str, Callable[[], Any]], dict[str, tuple[str, str]]]:
    """Name -> zero-argument call, and the pairs that must agree on the same parameters.

    The own rows are module calls with a params tree drawn once (validated, as a user's
    replayed call is); the kornia rows use the same numbers.
    """
    import kornia.augmentation as K
    from kornia.geometry.transform import (
        elastic_transform2d, get_perspective_transform, get_rotation_matrix2d, warp_affine, warp_perspective,
    )

    from event_transforms.functional.elastic import _gaussian_kernel
    from event_transforms.functional._warp import image_corners

    b, t, p, h, w = frames.shape
    generator = torch.Generator().manual_seed(seed)
    modules = {
        "own RandomRotation (centroid)": et.RandomRotation(180.0),
        "own RandomRotation (image centre)": et.RandomRotation(180.0, center="image"),
        "own RandomResize (centroid)": et.RandomResize(choices=(15 / 18, 15 / 12)),
        "own RandomPerspective": et.RandomPerspective(0.5),
        "own RandomElastic": et.RandomElastic(alpha=20.0, sigma=4.0),
    }
    params = {name: m.make_params(frames.shape, generator=generator) for name, m in modules.items()}
    folded = frames.reshape(b, t * p, h, w)
    ones = torch.ones(b, 2, dtype=frames.dtype)

    def kornia_rotate() -> torch.Tensor:
        center = F.center_of_mass(frames).flip(-1).to(frames.dtype)  # (B, 2) as (x, y)
        angle = params["own RandomRotation (centroid)"]["angle"].to(frames.dtype)
        return warp_affine(folded, get_rotation_matrix2d(center, angle, ones), (h, w), align_corners=True).view(frames.shape)

    def kornia_resize() -> torch.Tensor:
        center = F.center_of_mass(frames).flip(-1).to(frames.dtype)
        zoom = params["own RandomResize (centroid)"]["scale"].to(frames.dtype).unsqueeze(1).expand(b, 2)
        matrix = get_rotation_matrix2d(center, torch.zeros(b, dtype=frames.dtype), zoom)
        return warp_affine(folded, matrix, (h, w), align_corners=True).view(frames.shape)

    def kornia_perspective() -> torch.Tensor:
        corners = params["own RandomPerspective"]["corners"]
        source = image_corners(h, w).flip(-1).expand(b, 4, 2)
        matrix = get_perspective_transform(source, corners.flip(-1)).to(frames.dtype)
        return warp_perspective(folded, matrix, (h, w), align_corners=True).view(frames.shape)

    size = _gaussian_kernel(4.0, torch.device("cpu"), torch.float64).shape[0]
    noise = params["own RandomElastic"]["noise"].to(frames.dtype).flip(1)  # kornia: channel 0 is x
    alpha = (20.0 * 2 / (w - 1), 20.0 * 2 / (h - 1))

    def kornia_elastic() -> torch.Tensor:
        out = elastic_transform2d(folded, noise, (size, size), (4.0, 4.0), alpha, align_corners=True)
        return out.view(frames.shape)

    rotation = K.VideoSequential(K.RandomRotation(degrees=180.0, p=1.0), data_format="BTCHW", same_on_frame=True)
    perspective = K.VideoSequential(K.RandomPerspective(0.5, p=1.0), data_format="BTCHW", same_on_frame=True)
    elastic = K.VideoSequential(
        K.RandomElasticTransform(kernel_size=(size, size), sigma=(4.0, 4.0), alpha=alpha, p=1.0),
        data_format="BTCHW", same_on_frame=True,
    )
    cases: dict[str, Callable[[], Any]] = {BASELINE: frames.clone}
    for name, module in modules.items():
        cases[name] = lambda m=module, tree=params[name]: m(frames, params=tree)
    cases.update({
        "kornia warp_affine + get_rotation_matrix2d (centroid)": kornia_rotate,
        "kornia.augmentation VideoSequential(RandomRotation) (image centre)": lambda: rotation(frames),
        "kornia warp_affine, scale matrix (centroid)": kornia_resize,
        "kornia get_perspective_transform + warp_perspective": kornia_perspective,
        "kornia.augmentation VideoSequential(RandomPerspective)": lambda: perspective(frames),
        "kornia elastic_transform2d": kornia_elastic,
        "kornia.augmentation VideoSequential(RandomElasticTransform)": lambda: elastic(frames),
    })
    agree = {
        "rotation": ("own RandomRotation (centroid)", "kornia warp_affine + get_rotation_matrix2d (centroid)"),
        "resize": ("own RandomResize (centroid)", "kornia warp_affine, scale matrix (centroid)"),
        "perspective": ("own RandomPerspective", "kornia get_perspective_transform + warp_perspective"),
        "elastic": ("own RandomElastic", "kornia elastic_transform2d"),
    }
    return cases, agree


def run(shape: Sequence[int] = SHAPE, *, min_run_time: float = 0.2, rounds: int = 5) -> dict[str, Any]:
    frames = synthetic_frames(shape)
    cases, agree = build_cases(frames)
    counts = {name: count_ops(fn) for name, fn in cases.items()}
    timings, ratios = time_interleaved(cases, baseline=BASELINE, rounds=rounds, min_run_time=min_run_time)
    rows = []
    for name in cases:  # own rows first, then kornia's
        own = PAIRS.get(name)
        versus = fmt_ratio(ratios[name] / ratios[own]) + f" ({own})" if own else ""
        t = timings[name]
        rows.append([name, counts[name].ops, counts[name].syncs, fmt_ms(t.median), fmt_ms(t.iqr), fmt_ratio(ratios[name]), versus])
    table = markdown_table(["call", "ops", "host syncs", "median", "IQR", "× clone", "× own warp"], rows)
    differences = {
        what: float((cases[a]() - cases[b]()).abs().max()) for what, (a, b) in agree.items()
    }
    return {"table": table, "counts": counts, "timings": timings, "ratios": ratios, "differences": differences}


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    parser = base_parser(__doc__.splitlines()[0], "kornia_warp")
    parser.add_argument("--min-run-time", type=float, default=None, help="seconds per row and round (default 0.2, quick 0.02)")
    parser.add_argument("--rounds", type=int, default=None, help="interleaved rounds (default 5, quick 2)")
    args = parser.parse_args(argv)
    apply_threads(args.threads)
    shape = QUICK_SHAPE if args.quick else SHAPE
    min_run_time = args.min_run_time if args.min_run_time is not None else (0.02 if args.quick else 0.2)
    rounds = args.rounds if args.rounds is not None else (2 if args.quick else 5)
    result = run(shape, min_run_time=min_run_time, rounds=rounds)
    agreement = "; ".join(f"{what}: max |own − kornia| = {value:.1e}" for what, value in result["differences"].items())
    body = "\n\n".join(
        [
            "## kornia's warps against the own warp" + allocator_suffix(),
            f"Batch {tuple(shape)} float32, ≈5 % non-zero pixels; the same per-sample parameters for every "
            f"row; ops and host syncs from `torch.profiler` (top-level aten calls of one call); "
            f"{rounds} interleaved rounds of `torch.utils.benchmark.Timer.blocked_autorange` (min_run_time "
            f"{min_run_time} s per row and round), median and IQR of all blocks; '× clone' and '× own warp' "
            f"are medians over rounds of ratios timed in the same round. Command: `{command('library/kornia_warp.py', argv)}`.",
            "\n".join(environment_lines(("kornia",))),
            result["table"],
            f"Agreement on the same parameters: {agreement}.",
        ]
    )
    publish(body, args)
    return result


if __name__ == "__main__":
    main()
