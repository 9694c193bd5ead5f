"""Cost of each transform on a realistic batch, as a multiple of ``frames.clone()``.

The batch is (32, 36, 2, 70, 75) float32 event counts (the paper's 36 frames of 10 ms,
pooled to 70×75), about 5 % non-zero pixels holding small whole counts. Each module is
timed with ``torch.utils.benchmark.Timer.blocked_autorange`` and reported as a ratio to
``frames.clone()`` timed in the same run (the memory floor: one read and one write of the
batch). Rotation is also done the way a user would without this library:

- a per-sample loop of ``torchvision.transforms.v2.functional.rotate`` (own angle each);
- ``kornia.augmentation.VideoSequential(kornia.augmentation.RandomRotation(...))`` with
  ``data_format="BTCHW"`` and ``same_on_frame=True`` (one angle per sequence).

Run: ``python benchmarks/library/transforms.py`` (``--quick`` for a smoke run, ``--profile NAME``
to print where one row's time goes).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import torch

from benchmarks._common import (
    allocator_suffix, apply_threads, base_parser, command, environment_lines, fmt_ms, fmt_ratio, markdown_table,
    synthetic_frames, time_interleaved, publish,
)

import event_transforms as et

__all__ = ["build_cases", "peer_rotations", "floors", "GOALS", "run", "main"]

SHAPE = (32, 36, 2, 70, 75)
QUICK_SHAPE = (4, 6, 2, 17, 11)

# Goals: (row name, largest ratio to clone allowed).
GOALS: dict[str, float] = {
    "FrameShift(-1)": 1.5,
    "RandomFrameShift(±1, ±2)": 1.5,
    "HorizontalFlip": 1.5,
    "RandomHorizontalFlip(0.5)": 1.5,
    "VerticalFlip": 1.5,
    "RandomVerticalFlip(0.5)": 1.5,
    "Rotate(15°)": 4.0,
    "RandomRotation(±180°)": 4.0,
    "Resize(1.25)": 4.0,
    "RandomResize(15/18, 15/12)": 4.0,
    "AddNoise(static bank)": 2.0,
    "AddPoissonNoise(0.1–10 Hz)": 3.0,
    "TES-2(0.5) binomial": 3.0,
    "TES-2(0.5) exact": 6.0,
    "OneOf[RandomResize, FrameShift(-1), TES-2(0.5)] (independent)": 6.0,
}
ROTATION_SPEEDUP_GOAL = 3.0


def build_cases(frames: torch.Tensor) -> dict[str, Callable[[], Any]]:
    """Name -> zero-argument callable applying one module to ``frames`` (global RNG)."""
    t, _, h, w = frames.shape[1:]
    bank = synthetic_frames((max(4 * t, 40), 2, h, w), density=0.002, mean_count=1.0, seed=1)
    modules: dict[str, torch.nn.Module] = {
        "Rotate(15°)": et.Rotate(15.0),
        "Rotate(15°), center='image'": et.Rotate(15.0, center="image"),
        "RandomRotation(±180°)": et.RandomRotation(180.0),
        "RandomRotation(±180°), center='image'": et.RandomRotation(180.0, center="image"),
        "Resize(1.25)": et.Resize(1.25),
        "RandomResize(15/18, 15/12)": et.RandomResize(choices=(15 / 18, 15 / 12)),
        "FrameShift(-1)": et.FrameShift(-1),
        "RandomFrameShift(±1, ±2)": et.RandomFrameShift([-2, -1, 1, 2]),
        "TES-2(0.5) exact": et.TemporalEventShift(-2, 0.5, mode="exact"),
        "TES-2(0.5) binomial": et.TemporalEventShift(-2, 0.5, mode="binomial"),
        "TES-2(0.5) expected": et.TemporalEventShift(-2, 0.5, mode="expected"),
        "RandomTES(±1, ±2; ζ∈[0,1]) exact": et.RandomTemporalEventShift([-2, -1, 1, 2]),
        "AddNoise(static bank)": et.AddNoise(bank),
        "AddPoissonNoise(0.1–10 Hz)": et.AddPoissonNoise((0.1, 10.0)),
        "RandomEventDrop(0.1–0.5)": et.RandomEventDrop(fraction=(0.1, 0.5)),
        "HorizontalFlip": et.HorizontalFlip(),
        "RandomHorizontalFlip(0.5)": et.RandomHorizontalFlip(0.5),
        "VerticalFlip": et.VerticalFlip(),
        "RandomVerticalFlip(0.5)": et.RandomVerticalFlip(0.5),
        "OneOf[RandomResize, FrameShift(-1)] (independent)": et.OneOf(
            [et.RandomResize(choices=(15 / 18, 15 / 12)), et.FrameShift(-1)]
        ),
        "OneOf[RandomResize, FrameShift(-1), TES-2(0.5)] (independent)": et.OneOf(
            [et.RandomResize(choices=(15 / 18, 15 / 12)), et.FrameShift(-1), et.TemporalEventShift(-2, 0.5)]
        ),
        "Compose[RandomResize, FrameShift(-1)] (hybrid)": et.Compose(
            [et.RandomResize(choices=(15 / 18, 15 / 12)), et.FrameShift(-1)]
        ),
    }
    return {name: (lambda m=module: m(frames)) for name, module in modules.items()}


def peer_rotations(frames: torch.Tensor, degrees: float = 180.0) -> dict[str, Callable[[], Any]]:
    """Rotation of ``frames`` the way a user would without this library (per-sample angles)."""
    import kornia.augmentation as K
    import torchvision.transforms.v2.functional as TF
    from torchvision.transforms import InterpolationMode

    b = frames.shape[0]

    def torchvision_loop() -> torch.Tensor:
        angles = (torch.rand(b) * 2 - 1) * degrees
        return torch.stack(
            [TF.rotate(frames[i], float(angles[i]), interpolation=InterpolationMode.BILINEAR) for i in range(b)]
        )

    video = K.VideoSequential(
        K.RandomRotation(degrees=degrees, p=1.0), data_format="BTCHW", same_on_frame=True
    )

    def kornia_video() -> torch.Tensor:
        return video(frames)

    return {
        "torchvision v2 rotate, per-sample loop": torchvision_loop,
        "kornia VideoSequential(RandomRotation)": kornia_video,
    }


def floors(frames: torch.Tensor) -> dict[str, Callable[[], Any]]:
    """The single calls that bound the kernels from below on the CPU (for the explanation
    of the goals that are missed): the ``nonzero`` of the batch that the event-level
    kernels need, and one ``grid_sample`` of the folded batch with a fixed grid."""
    b, t, p, h, w = frames.shape
    bits = frames.reshape(-1).view(torch.int32)
    theta = torch.tensor([[0.96, -0.26, 0.0], [0.26, 0.96, 0.0]]).expand(b, 2, 3)
    grid = torch.nn.functional.affine_grid(theta, [b, t * p, h, w], align_corners=True)
    folded = frames.reshape(b, t * p, h, w)
    return {
        "nonzero of the batch (float bits as int32)": lambda: bits.nonzero(),
        "grid_sample of the folded batch, bilinear": lambda: torch.nn.functional.grid_sample(
            folded, grid, mode="bilinear", padding_mode="zeros", align_corners=True
        ),
    }


def _speed(speedup: float) -> str:
    """'2.0× faster' or '1.5× slower' from a time ratio peer / ours."""
    return f"{speedup:.1f}× faster" if speedup >= 1 else f"{1 / speedup:.1f}× slower"


def _goal_cell(name: str, ratio: float) -> str:
    goal = GOALS.get(name)
    if goal is None:
        return ""
    return f"≤ {goal:g}× {'met' if ratio <= goal else 'MISSED'}"


def run(
    shape: Sequence[int] = SHAPE,
    *,
    min_run_time: float = 0.2,
    rounds: int = 5,
    only: Sequence[str] | None = None,
) -> dict[str, Any]:
    """Time every case; returns the clone baseline, per-row timings and the table text."""
    frames = synthetic_frames(shape)
    cases = {"frames.clone() (baseline)": frames.clone, **build_cases(frames)}
    peers = peer_rotations(frames)
    bounds = floors(frames)
    if only:
        cases = {k: v for k, v in cases.items() if k == "frames.clone() (baseline)" or k in only}
        peers = {k: v for k, v in peers.items() if k in only}
        bounds = {k: v for k, v in bounds.items() if k in only}
    baseline = "frames.clone() (baseline)"
    timings, ratios = time_interleaved(
        {**cases, **peers, **bounds}, baseline=baseline, rounds=rounds, min_run_time=min_run_time
    )
    clone = timings[baseline]

    rows = []
    for name in cases:
        t = timings[name]
        rows.append([name, fmt_ms(t.median), fmt_ms(t.iqr), fmt_ratio(ratios[name]), _goal_cell(name, ratios[name])])
    for name in peers:
        t = timings[name]
        rows.append([f"*peer:* {name}", fmt_ms(t.median), fmt_ms(t.iqr), fmt_ratio(ratios[name]), ""])
    for name in bounds:
        t = timings[name]
        rows.append([f"*floor:* {name}", fmt_ms(t.median), fmt_ms(t.iqr), fmt_ratio(ratios[name]), ""])
    table = markdown_table(["transform", "median", "IQR", "× clone", "goal"], rows)

    summary = []
    ours = timings.get("RandomRotation(±180°)")
    if ours is not None and peers:
        for name in peers:
            speedup = ratios[name] / ratios["RandomRotation(±180°)"]
            verdict = "met" if speedup >= ROTATION_SPEEDUP_GOAL else "MISSED"
            summary.append(
                f"- RandomRotation (per-sample angles, mass centre): {_speed(speedup)} than "
                f"{name} (goal ≥ {ROTATION_SPEEDUP_GOAL:g}× faster: {verdict})."
            )
        ours_image = "RandomRotation(±180°), center='image'"
        if ours_image in ratios:
            for name in peers:
                summary.append(
                    f"- RandomRotation with the peers' centre (image centre): "
                    f"{_speed(ratios[name] / ratios[ours_image])} than {name}."
                )
    missed = [n for n in GOALS if n in ratios and ratios[n] > GOALS[n]]
    summary.append("- Goals missed: " + (", ".join(missed) if missed else "none") + ".")
    return {"clone": clone, "timings": timings, "ratios": ratios, "table": table, "summary": "\n".join(summary), "shape": tuple(shape)}


def profile(name: str, shape: Sequence[int] = SHAPE, *, rows: int = 15) -> str:
    """``torch.profiler`` table of one case (by row name), self CPU time first."""
    frames = synthetic_frames(shape)
    cases = {**build_cases(frames), **peer_rotations(frames)}
    if name not in cases:
        raise ValueError(f"name must be one of {sorted(cases)}, got {name!r}")
    fn = cases[name]
    fn()
    from torch.profiler import ProfilerActivity, profile as torch_profile

    with torch_profile(activities=[ProfilerActivity.CPU]) as prof:
        for _ in range(5):
            fn()
    return prof.key_averages().table(sort_by="self_cpu_time_total", row_limit=rows)


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    parser = base_parser(__doc__.splitlines()[0], "transforms")
    parser.add_argument("--min-run-time", type=float, default=None, help="seconds per row and round (default 0.2, quick 0.02)")
    parser.add_argument("--rounds", type=int, default=None, help="interleaved rounds (default 5, quick 2)")
    parser.add_argument("--profile", default=None, metavar="NAME", help="print a torch.profiler table of one row")
    parser.add_argument("--only", nargs="*", default=None, help="time only these rows (plus the baseline)")
    args = parser.parse_args(argv)
    apply_threads(args.threads)
    shape = QUICK_SHAPE if args.quick else SHAPE
    if args.profile:
        print(profile(args.profile, shape))
        return {}
    min_run_time = args.min_run_time if args.min_run_time is not None else (0.02 if args.quick else 0.2)
    rounds = args.rounds if args.rounds is not None else (2 if args.quick else 5)
    result = run(shape, min_run_time=min_run_time, rounds=rounds, only=args.only)
    cmd = command("library/transforms.py", argv)
    density = "≈5 % non-zero pixels, counts 1 + Poisson(0.5)"
    body = "\n\n".join(
        [
            "## Transforms: cost per batch as a multiple of `frames.clone()`" + allocator_suffix(),
            f"Batch {tuple(shape)} float32, {density}; global RNG; "
            f"{rounds} interleaved rounds of `torch.utils.benchmark.Timer.blocked_autorange` (min_run_time "
            f"{min_run_time} s per row and round); median and IQR of all blocks; '× clone' is the median over "
            f"rounds of the ratio to `frames.clone()` timed in the same round. "
            f"Command: `{cmd}`.",
            "\n".join(environment_lines()),
            result["table"],
            result["summary"],
        ]
    )
    publish(body, args)
    return result


if __name__ == "__main__":
    main()
