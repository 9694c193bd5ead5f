"""Temporal event shifting and rotation of a batch of simulated grasps, done five ways.

Data: ``B`` grasps from :mod:`event_transforms.tactile.simulation` (12 and 18 mm bolts), kept both
as raw event streams and as the paper's frames (36 × 10 ms, 140×150 crop around the
contact, 2×2 sum-pooled to 70×75). Each way produces a batch of augmented frames
``(B, 36, 2, 70, 75)``; we report samples per second and how many times faster the
library's per-batch call is.

(a) **per batch**: this library's module on the whole batch (one call).
(b) **per sample in workers**: the same module applied to each ``(T, 2, H, W)`` sample in
    ``Dataset.__getitem__``, batched by a ``DataLoader`` with ``num_workers`` workers
    (persistent, so start-up is not timed).
(c) **tonic style, on events**: what a tonic user writes, per sample: augment the event
    stream in numpy (tonic has neither TES nor rotation, so: shift a random ζ share of the
    events by j·10 ms; rotate event coordinates about the contact centre and round), then
    ``tonic.transforms.ToFrame`` (10 ms windows), crop and pool. Falls back to the same
    binning in numpy if tonic is not installed (reported).
(d) **torchvision v2 / kornia per sample** (rotation only; neither has TES):
    ``torchvision.transforms.v2.functional.rotate`` on each ``(T, 2, H, W)`` sample with its
    own angle, and ``kornia.augmentation.VideoSequential(RandomRotation)`` called per sample.
(e) **per-frame Python loop** (TES only), as BrainCog's ``TemporalShift`` is described:
    for each sample and frame, draw which events move (a binomial draw per pixel), move them.

Run: ``python benchmarks/library/peers.py`` (``--quick`` for a smoke run).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset

from benchmarks._common import (
    apply_threads, base_parser, command, environment_lines, fmt_ms, markdown_table,
    time_interleaved, publish,
)

import event_transforms as et
from event_transforms.tactile.simulation import SimulatorConfig, draw_grasp, simulate_grasps

__all__ = ["load_samples", "build_cases", "run", "main"]

SHIFT, FRACTION = -2, 0.5  # the paper's TES-2(0.50)
DEGREES = 180.0
POOL = 2
CROP = (140, 150)
TES_GOALS = {"tonic": 10.0, "torchvision/kornia": 3.0}


def load_samples(batch: int, seed: int = 0) -> dict[str, Any]:
    """Simulate ``batch`` grasps: their event streams, crops and frames (B, 36, 2, 70, 75)."""
    config = SimulatorConfig()
    grasps = [draw_grasp((12.0, 18.0)[i % 2], gripper=(i // 2) % len(config.gripper_force_n), seed=seed + i, config=config) for i in range(batch)]
    recordings = simulate_grasps(grasps, config)
    crops = [r.contact_crop(CROP) for r in recordings]
    frames = torch.stack([r.frames(crop=c, pool=POOL) for r, c in zip(recordings, crops)])
    return {"config": config, "events": [r.events for r in recordings], "crops": crops, "frames": frames}


# --------------------------------------------------------------------------- (c) tonic style


def _tonic_to_frame(config: SimulatorConfig) -> tuple[Callable[[np.ndarray], np.ndarray], str]:
    height, width = config.sensor_size
    duration_us = int(round(config.duration_ms * 1000))
    window_us = int(round(config.frame_ms * 1000))
    try:
        import tonic.transforms as tonic_transforms
    except ImportError:
        def to_frame(events: np.ndarray) -> np.ndarray:
            frame = np.clip(events["t"] // window_us, 0, None)
            keep = frame < config.n_frames
            out = np.zeros((config.n_frames, 2, height, width), dtype=np.int16)
            np.add.at(out, (frame[keep], events["p"][keep], events["y"][keep], events["x"][keep]), 1)
            return out

        return to_frame, "numpy binning (tonic not installed)"
    transform = tonic_transforms.ToFrame(
        sensor_size=(width, height, 2), time_window=window_us, start_time=0, end_time=duration_us
    )
    import tonic

    return transform, f"tonic {tonic.__version__} ToFrame"


def _crop_pool(frames: np.ndarray, crop: tuple[int, int, int, int]) -> torch.Tensor:
    top, left, h, w = crop
    window = frames[:, :, top : top + h, left : left + w]
    t, p = window.shape[:2]
    pooled = window.reshape(t, p, h // POOL, POOL, w // POOL, POOL).sum(axis=(3, 5))
    return torch.from_numpy(pooled.astype(np.float32))


def tonic_tes(events: np.ndarray, rng: np.random.Generator, window_us: int) -> np.ndarray:
    """Shift a random ``FRACTION`` of the events by ``SHIFT`` frames; drop those leaving the recording."""
    events = events.copy()
    moved = rng.random(len(events)) < FRACTION
    events["t"][moved] += SHIFT * window_us
    return events[events["t"] >= 0]


def tonic_rotation(events: np.ndarray, rng: np.random.Generator, center_yx: tuple[float, float], size: tuple[int, int]) -> np.ndarray:
    """Rotate event coordinates about ``center_yx`` by a random angle; drop events leaving the sensor."""
    angle = math.radians(rng.uniform(-DEGREES, DEGREES))
    cy, cx = center_yx
    x = events["x"].astype(np.float64) - cx
    y = events["y"].astype(np.float64) - cy
    xr = np.rint(cx + math.cos(angle) * x - math.sin(angle) * y)
    yr = np.rint(cy + math.sin(angle) * x + math.cos(angle) * y)
    keep = (xr >= 0) & (xr < size[1]) & (yr >= 0) & (yr < size[0])
    out = events[keep].copy()
    out["x"], out["y"] = xr[keep], yr[keep]
    return out


# --------------------------------------------------------------------------- (e) per-frame loop


def per_frame_loop_tes(sample: torch.Tensor) -> torch.Tensor:
    """TES of one (T, 2, H, W) sample with a Python loop over frames (BrainCog-style)."""
    out = sample.clone()
    t_len = sample.shape[0]
    for t in range(t_len):
        moved = torch.binomial(sample[t], torch.full_like(sample[t], FRACTION))
        out[t] -= moved
        if 0 <= t + SHIFT < t_len:
            out[t + SHIFT] += moved
    return out


# --------------------------------------------------------------------------- (b) workers


class _PerSample(Dataset):
    def __init__(self, frames: torch.Tensor, transform: torch.nn.Module) -> None:
        self.frames = frames
        self.transform = transform

    def __len__(self) -> int:
        return self.frames.shape[0]

    def __getitem__(self, index: int) -> torch.Tensor:
        return self.transform(self.frames[index])


def _worker_epoch(frames: torch.Tensor, transform: torch.nn.Module, workers: int) -> tuple[Callable[[], Any], DataLoader]:
    """One pass over ``frames`` through a DataLoader whose workers transform sample by sample.

    The batch is split into ``workers`` loader batches so that every worker has work; the
    workers are persistent, so their start-up is paid once, before timing.
    """
    loader = DataLoader(
        _PerSample(frames, transform),
        batch_size=max(1, math.ceil(frames.shape[0] / max(workers, 1))),
        num_workers=workers,
        persistent_workers=workers > 0,
    )
    return (lambda: torch.cat(list(loader))), loader


def build_cases(
    data: dict[str, Any], workers: int = 2
) -> tuple[dict[str, dict[str, Callable[[], Any]]], list[DataLoader], str]:
    """Operation -> (way -> callable producing the augmented batch); the loaders of (b) (to
    shut down); and the binning used in (c)."""
    import kornia.augmentation as K
    import torchvision.transforms.v2.functional as TF
    from torchvision.transforms import InterpolationMode

    frames, events, crops, config = data["frames"], data["events"], data["crops"], data["config"]
    batch = frames.shape[0]
    window_us = int(round(config.frame_ms * 1000))
    to_frame, binning = _tonic_to_frame(config)
    rng = np.random.default_rng(0)

    tes = et.TemporalEventShift(SHIFT, FRACTION, mode="exact")
    tes_binomial = et.TemporalEventShift(SHIFT, FRACTION, mode="binomial")
    rotation = et.RandomRotation(DEGREES)
    tes_epoch, tes_loader = _worker_epoch(frames, tes, workers)
    rot_epoch, rot_loader = _worker_epoch(frames, rotation, workers)

    def tonic_tes_batch() -> torch.Tensor:
        return torch.stack([_crop_pool(to_frame(tonic_tes(e, rng, window_us)), c) for e, c in zip(events, crops)])

    def tonic_rotation_batch() -> torch.Tensor:
        out = []
        for e, (top, left, h, w) in zip(events, crops):
            center = (top + (h - 1) / 2, left + (w - 1) / 2)
            out.append(_crop_pool(to_frame(tonic_rotation(e, rng, center, config.sensor_size)), (top, left, h, w)))
        return torch.stack(out)

    def torchvision_per_sample() -> torch.Tensor:
        angles = (torch.rand(batch) * 2 - 1) * DEGREES
        return torch.stack(
            [TF.rotate(frames[i], float(angles[i]), interpolation=InterpolationMode.BILINEAR) for i in range(batch)]
        )

    video = K.VideoSequential(K.RandomRotation(degrees=DEGREES, p=1.0), data_format="BTCHW", same_on_frame=True)

    def kornia_per_sample() -> torch.Tensor:
        return torch.cat([video(frames[i : i + 1]) for i in range(batch)])

    cases = {
        "TES-2(0.5)": {
            "(a) per batch, exact": lambda: tes(frames),
            "(a) per batch, binomial": lambda: tes_binomial(frames),
            f"(b) per sample, DataLoader num_workers={workers}": tes_epoch,
            f"(c) tonic style: numpy on events + {binning}": tonic_tes_batch,
            "(e) per-frame Python loop (BrainCog-style)": lambda: torch.stack([per_frame_loop_tes(s) for s in frames]),
        },
        "RandomRotation(±180°)": {
            "(a) per batch": lambda: rotation(frames),
            f"(b) per sample, DataLoader num_workers={workers}": rot_epoch,
            f"(c) tonic style: rotate event coordinates + {binning}": tonic_rotation_batch,
            "(d) torchvision v2 rotate, per sample": torchvision_per_sample,
            "(d) kornia VideoSequential, per sample": kornia_per_sample,
        },
    }
    return cases, [tes_loader, rot_loader], binning


def run(batch: int = 32, *, workers: int = 2, rounds: int = 3, min_run_time: float = 0.5) -> dict[str, Any]:
    data = load_samples(batch)
    cases, loaders, binning = build_cases(data, workers)
    results: dict[str, Any] = {"binning": binning, "batch": batch, "events_per_sample": float(np.mean([len(e) for e in data["events"]]))}
    try:
        for operation, ways in cases.items():
            baseline = next(iter(ways))
            timings, ratios = time_interleaved(ways, baseline=baseline, rounds=rounds, min_run_time=min_run_time)
            results[operation] = {"baseline": baseline, "timings": timings, "ratios": ratios}
    finally:
        for loader in loaders:
            iterator = getattr(loader, "_iterator", None)
            if iterator is not None:
                iterator._shutdown_workers()
    return results


def tables(result: dict[str, Any]) -> str:
    batch = result["batch"]
    parts = []
    for operation in ("TES-2(0.5)", "RandomRotation(±180°)"):
        r = result[operation]
        rows = []
        for way, timing in r["timings"].items():
            speedup = r["ratios"][way]  # time of this way / time of (a)
            rows.append([way, fmt_ms(timing.median), f"{batch / timing.median:,.0f}", "1" if way == r["baseline"] else f"{speedup:.1f}×"])
        parts += [f"**{operation}**, batch of {batch}:", markdown_table(["way", "time per batch", "samples/s", "(a) is faster by"], rows)]
    goals = []
    for operation in ("TES-2(0.5)", "RandomRotation(±180°)"):
        r = result[operation]
        for way, ratio in r["ratios"].items():
            if way.startswith("(c)"):
                goals.append(f"- {operation}: (a) vs (c) tonic style: {ratio:.1f}× (goal ≥ 10×: {'met' if ratio >= 10 else 'MISSED'}).")
            if way.startswith("(d)"):
                goals.append(f"- {operation}: (a) vs {way[4:]}: {ratio:.1f}× (goal ≥ 3×: {'met' if ratio >= 3 else 'MISSED'}).")
    return "\n\n".join(parts + ["\n".join(goals)])


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    parser = base_parser(__doc__.splitlines()[0], "peers")
    parser.add_argument("--batch", type=int, default=None, help="samples (default 32, quick 4)")
    parser.add_argument("--workers", type=int, default=2, help="DataLoader workers in (b) (default 2)")
    parser.add_argument("--rounds", type=int, default=None, help="interleaved rounds (default 3, quick 1)")
    parser.add_argument("--min-run-time", type=float, default=None, help="seconds per way and round (default 0.5)")
    args = parser.parse_args(argv)
    apply_threads(args.threads)
    batch = args.batch or (4 if args.quick else 32)
    rounds = args.rounds or (1 if args.quick else 3)
    min_run_time = args.min_run_time if args.min_run_time is not None else (0.01 if args.quick else 0.5)
    result = run(batch, workers=args.workers, rounds=rounds, min_run_time=min_run_time)
    body = "\n\n".join(
        [
            "## Peers: TES and rotation of simulated grasps, five ways",
            f"{batch} simulated grasps (≈{result['events_per_sample']:,.0f} events each on the 240×180 sensor; frames "
            f"(36, 2, 70, 75) after a 140×150 crop and 2×2 pooling). (c) includes binning the events to frames "
            f"({result['binning']}), since an events-level augmentation must re-bin every epoch. "
            f"{rounds} interleaved rounds of `blocked_autorange` (min_run_time {min_run_time} s); "
            f"'(a) is faster by' = median over rounds of time(way) / time(a) in the same round. "
            f"Command: `{command('library/peers.py', argv)}`.",
            "\n".join(environment_lines(("tonic",))),
            tables(result),
        ]
    )
    publish(body, args)
    return result


if __name__ == "__main__":
    main()
