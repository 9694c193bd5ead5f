"""The DVS emulator's speed and memory against the video's real duration, on one CPU thread.

``functional.emulate_events`` on a 30 frames/s luminance video of the rectified gel crop
(370 × 400, the GelSight Wedge's gel as the ``convert`` command rectifies it), timed in the
same run as a baseline that every pipeline pays anyway (one ``clone`` of the video tensor),
and printed as a ratio to real time (video seconds per second of emulation; the goal is
>= 10). Three cameras: ideal (thresholds with mismatch only), with a refractory period, and
with shot noise, hot pixels and leak (v2e-like rates). The video is synthetic (a disc
pressed into a textured gel over 222 frames, 7.4 s, like a 2023-12-16 grasp), so the script
runs anywhere; with ``--data DIR`` (the GelSight Wedge folder, never copied) it also decodes
and emulates every recorded grasp, twice (the first pass reads the files from disk or the
page cache, the second from the page cache) and reports the cost per grasp and for the set.

Peak memory: each length runs in a fresh process; the table gives the peak resident set
above the process that built the video (``VmHWM``), for 222 and 888 frames: the frames are
read in chunks, so the peak does not grow with the video beyond its events.

    MALLOC_MMAP_THRESHOLD_=1073741824 MALLOC_TRIM_THRESHOLD_=1073741824 \\
        python benchmarks/library/emulate.py [--quick] [--data ../shared/data/gelsight-wedge] [--no-write]
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from pathlib import Path

import torch

from benchmarks._common import allocator_suffix, base_parser, command, environment_lines, markdown_table, publish, time_repeated

from event_transforms.functional import emulate_events

SIZE = (370, 400)
FPS = 30.0
CAMERAS = {
    "ideal (θ 0.2, mismatch 0.03)": dict(threshold_on=0.2, mismatch=0.03),
    "refractory 1 ms": dict(threshold_on=0.2, mismatch=0.03, refractory_us=1000.0),
    "noise 1 Hz, hot 1e-4 at 100 Hz, leak 0.1 Hz": dict(threshold_on=0.2, mismatch=0.03, noise_hz=1.0,
                                                         hot_pixel_fraction=1e-4, leak_hz=0.1),
}


def pressing_video(frames: int, size: tuple[int, int] = SIZE, seed: int = 0) -> torch.Tensor:
    """A textured gel (luminance in [0.25, 0.75]) darkened by a disc pressed in and released."""
    generator = torch.Generator().manual_seed(seed)
    height, width = size
    texture = 0.5 + 0.25 * torch.rand(height, width, generator=generator).sub_(0.5).mul_(2)
    y, x = torch.meshgrid(torch.arange(height, dtype=torch.float32), torch.arange(width, dtype=torch.float32),
                          indexing="ij")
    distance = ((y - height / 2) ** 2 + (x - width / 2) ** 2).sqrt()
    press = torch.sin(torch.linspace(0, math.pi, frames)).clamp_min(0)  # in and out
    video = torch.empty(frames, height, width)
    for k in range(frames):  # frame by frame: no temporaries of the video's size
        inside = (distance < 20 + 80 * float(press[k])).float()
        torch.mul(texture, 1 - 0.6 * float(press[k]) * inside, out=video[k])
    return video


def _peak(frames: int) -> dict[str, float]:
    """Run one emulation in a fresh process: its peak resident set above the built video, MiB."""
    code = f"""
import json, torch, sys
sys.path.insert(0, {str(Path(__file__).resolve().parents[2])!r})
torch.set_num_threads(1)
from benchmarks.library.emulate import pressing_video
from event_transforms.functional import emulate_events
def hwm():
    for line in open('/proc/self/status'):
        if line.startswith('VmHWM'):
            return int(line.split()[1]) / 1024
video = pressing_video({frames})
emulate_events(video[:3], fps=30.0, seed=0)
base = hwm()
events = emulate_events(video, fps=30.0, threshold_on=0.2, mismatch=0.03, seed=0)
print(json.dumps({{"peak": hwm() - base, "events": events.num_events, "video": video.numel() * 4 / 2**20}}))
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _dataset(root: Path, quick: bool) -> list[str]:
    from event_transforms.tactile.recordings.video import VideoEmulation, iter_video, video_luminance

    videos = sorted(root.glob("*/*.avi"))[: 2 if quick else None]
    settings = VideoEmulation()
    rows, totals = [], {}
    for label in ("first pass", "second pass"):
        decode = rectify = emulate = duration = 0.0
        for video in videos:
            start = time.perf_counter()
            for _ in iter_video(video):
                pass
            decode += time.perf_counter() - start
            start = time.perf_counter()
            luminance, times = video_luminance(video, settings)
            rectify += time.perf_counter() - start
            start = time.perf_counter()
            emulate_events(luminance, frame_times_us=torch.from_numpy(times), threshold_on=settings.threshold,
                           mismatch=settings.mismatch, seed=0)
            emulate += time.perf_counter() - start
            duration += (times[-1] - times[0]) / 1e6 + 1 / FPS
        totals[label] = (decode, rectify, emulate, duration)
        n = len(videos)
        rows.append([label, f"{n}", f"{duration:.1f} s", f"{decode:.2f} s ({1000 * decode / n:.0f} ms)",
                     f"{rectify:.2f} s ({1000 * rectify / n:.0f} ms)", f"{emulate:.2f} s ({1000 * emulate / n:.0f} ms)",
                     f"{duration / (rectify + emulate):.1f}×"])
    return ["", f"Recorded grasps in `{root.name}` (45 GelSight Wedge videos, 640×480 MJPG; files read, never copied):", "",
            markdown_table(["pass", "grasps", "video", "decode only (per grasp)", "decode + crop + luminance (per grasp)",
                            "emulation (per grasp)", "real time / (decode + crop + emulation)"], rows)]


def main(argv: list[str] | None = None) -> None:
    parser = base_parser(__doc__.splitlines()[0], "emulate")
    parser.add_argument("--data", type=Path, default=None, help="the GelSight Wedge folder (optional)")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    frames = 31 if args.quick else 222
    size = (74, 80) if args.quick else SIZE
    video = pressing_video(frames, size)
    duration = frames / FPS
    clone = time_repeated(video.clone, repeats=3 if args.quick else 7)
    rows = []
    for name, camera in CAMERAS.items():
        timing = time_repeated(lambda camera=camera: emulate_events(video, fps=FPS, seed=0, **camera),
                               repeats=2 if args.quick else 5)
        events = emulate_events(video, fps=FPS, seed=0, **camera).num_events
        rows.append([name, f"{events:,}", f"{1000 * timing.median:.0f} ms (IQR {1000 * timing.iqr:.0f})",
                     f"{timing.median / clone.median:.0f}×", f"{duration / timing.median:.1f}×"])
    lines = [
        f"## DVS emulation (`functional.emulate_events`), one CPU thread{allocator_suffix()}", "",
        *environment_lines(), "", f"Command: `{command('library/emulate.py', argv)}`", "",
        f"A {frames}-frame 30 frames/s video ({duration:.1f} s) of {size[0]}×{size[1]} pixels (the rectified gel crop), "
        f"float32 luminance; baseline: one clone of the video, {1000 * clone.median:.1f} ms.", "",
        markdown_table(["camera", "events", "emulation (median)", "vs clone", "real time / emulation"], rows),
    ]
    if not args.quick:
        peaks = [(n, _peak(n)) for n in (222, 888)]
        lines += ["", "Peak resident memory above the built video (fresh process each, ideal camera):", "",
                  markdown_table(["frames", "video (float32)", "events", "peak above the video"],
                                 [[n, f"{p['video']:.0f} MiB", f"{p['events']:,}", f"{p['peak']:.0f} MiB"]
                                  for n, p in peaks])]
    if args.data is not None:
        if not args.data.is_dir():
            raise SystemExit(f"--data {args.data}: no such folder")
        lines += _dataset(args.data, args.quick)
    publish("\n".join(lines), args)


if __name__ == "__main__":
    main()
