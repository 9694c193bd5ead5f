"""Choose the converter's emulator settings (colour channel, threshold, crop) on training grasps only.

The measurement the issue names: for each recorded grasp, the Pearson correlation between
the emulated events per frame interval and the force's change |ΔF| over the same interval;
its median over the grasps. Only grasps that are training data in every natural split of
the GelSight Wedge set are read: the hardest and the softest ball of 2023-12-06
(``purple_ball_hardest_*``, ``orange_ball_softest_*``: the extremes of the hardness
interpolation, on the day that the session split trains on, and spheres, the training
shape of the shape split), six grasps. Every other grasp is left unread, so the choice
cannot have seen a deployment recording.

Candidates: the gel's quadrilateral rectified to 370 × 400 (:data:`GEL_CORNERS_XY`) or the
naive bounding box (x 60-480, y 60-440, unrectified, mean of RGB only: the README's naive
emulation); channel mean of RGB, BT.601 luma, red, green or blue; thresholds 0.03-0.4.
The chosen setting maximises the median correlation (ties: the larger threshold, fewer
events). Only aggregate numbers are printed.

    python benchmarks/tactile/video_settings.py --data ../shared/data/gelsight-wedge [--no-write]
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from benchmarks._common import base_parser, command, environment_lines, markdown_table, publish

from event_transforms.functional import emulate_events
from event_transforms.tactile.recordings.video import (GEL_CORNERS_XY, GEL_SIZE, VideoEmulation, read_array_pickle,
                                                       video_luminance)

TRAINING = ("2023-12-06/purple_ball_hardest_*.avi", "2023-12-06/orange_ball_softest_*.avi")
CHANNELS = ("mean", "luma", 0, 1, 2)
THRESHOLDS = (0.03, 0.05, 0.07, 0.1, 0.15, 0.2, 0.3, 0.4)
#: The naive crop: the gel's bounding box with its border, unrectified (x from 60 to 480, y from 60 to 440).
BOX = ((60.0, 60.0), (479.0, 60.0), (479.0, 439.0), (60.0, 439.0))
CHANNEL_NAMES = {"mean": "mean RGB", "luma": "luma (BT.601)", 0: "red", 1: "green", 2: "blue"}


def events_per_interval(luminance: torch.Tensor, times: np.ndarray, threshold: float) -> np.ndarray:
    """Events emulated in each frame interval [t_k, t_{k+1}), (T - 1,)."""
    events = emulate_events(luminance, frame_times_us=torch.from_numpy(times - times[0]), threshold_on=threshold,
                            mismatch=0.03, seed=0, camera_seed=0)
    edges = times - times[0]
    counts = np.histogram(events.t.numpy(), bins=np.append(edges[:-1], edges[-1] + 1))[0]
    return counts.astype(np.float64)


def correlation(a: np.ndarray, b: np.ndarray) -> float:
    if a.std() == 0 or b.std() == 0:
        return float("nan")
    return float(np.corrcoef(a, b)[0, 1])


def main(argv: list[str] | None = None) -> None:
    parser = base_parser(__doc__.splitlines()[0], "video-settings")
    parser.add_argument("--data", type=Path, required=True, help="the GelSight Wedge folder")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    videos = sorted(v for pattern in TRAINING for v in args.data.glob(pattern))
    if args.quick:
        videos = videos[:2]
    if not videos:
        raise SystemExit(f"--data {args.data}: no training grasp found ({', '.join(TRAINING)})")
    crops = {"gel quadrilateral, rectified 370×400": (GEL_CORNERS_XY, GEL_SIZE), "bounding box 380×420": (BOX, (380, 420))}
    scores: dict[tuple[str, object, float], list[float]] = {}
    rates: dict[tuple[str, object, float], list[float]] = {}
    for video in videos:
        force = read_array_pickle(video.with_name(video.stem + "_forces.pkl"))
        change = np.abs(np.diff(np.maximum(force, 0.0)))
        for crop, (corners, size) in crops.items():
            for channel in CHANNELS if crop.startswith("gel") else ("mean",):
                settings = VideoEmulation(channel=channel, corners_xy=corners, size=size)
                luminance, times = video_luminance(video, settings)
                for threshold in THRESHOLDS:
                    counts = events_per_interval(luminance, times, threshold)
                    key = (crop, channel, threshold)
                    scores.setdefault(key, []).append(correlation(counts, change))
                    rates.setdefault(key, []).append(float(counts.mean()))
    rows = []
    best = None
    for key in scores:
        median = float(np.nanmedian(scores[key]))
        rows.append([key[0], CHANNEL_NAMES[key[1]], f"{key[2]:g}", f"{median:+.2f}", f"{np.nanmin(scores[key]):+.2f}",
                     f"{np.median(rates[key]):,.0f}"])
        if best is None or (median, key[2]) > (best[0], best[1][2]):
            best = (median, key)
    assert best is not None
    lines = [
        "## The converter's emulator settings, chosen on training grasps", "", *environment_lines(), "",
        f"Command: `{command('tactile/video_settings.py', argv)}`", "",
        f"{len(videos)} training grasps ({', '.join(TRAINING)}); per grasp the Pearson correlation of emulated events "
        "per frame interval with |ΔF| over it (negative force readings clipped to 0 N first); mismatch 0.03, no "
        "refractory period, no emulated noise. Aggregates only.", "",
        markdown_table(["crop", "channel", "threshold", "median r", "worst r", "median events per interval"], rows), "",
        f"Chosen: {best[1][0]}, {CHANNEL_NAMES[best[1][1]]}, threshold {best[1][2]:g} (median r {best[0]:+.2f}).",
    ]
    publish("\n".join(lines), args)


if __name__ == "__main__":
    main()
