"""Peak memory of the size-changing event kernels (exact TES, binomial TES, frame shift, event drop)
on one batch of about 10**7 events, as a multiple of the batch's own bytes (the goal: exact TES's
fix-up within 3x the batch at 10**7 events).

Each kernel runs in a fresh process: the batch is built, the process's peak resident size
(``VmHWM``) is reset through ``/proc/self/clear_refs`` (Linux), the kernel runs, and the
peak minus the resident size before the call is the kernel's extra memory (its output
included). Large tensors are mmap'ed by glibc by default and returned when freed, so the
figure is the kernel's true peak; the allocator tuning of the timing benchmarks is *not*
used here.

Usage (from the repository root; writes the ``tes-memory`` section of ``benchmarks/library/RESULTS.md``)::

    python -m benchmarks.library.tes_memory [--events 10000000] [--streams 32] [--no-write]
"""

from __future__ import annotations

import subprocess
import sys

from benchmarks._common import base_parser, child_env, command, environment_lines, publish

CASES = ("TES exact", "TES binomial", "FrameShift", "RandomEventDrop(random)")


def _status(field: str) -> int:
    with open("/proc/self/status") as handle:
        for line in handle:
            if line.startswith(field + ":"):
                return int(line.split()[1]) * 1024
    raise RuntimeError(field)


def child(case: str, events: int, streams: int) -> None:
    import torch

    import event_transforms as et
    from event_transforms.events.batch import EventBatch

    torch.set_num_threads(1)
    per = events // streams
    g = torch.Generator().manual_seed(0)
    x = torch.randint(0, 320, (events,), generator=g, dtype=torch.int16)
    y = torch.randint(0, 240, (events,), generator=g, dtype=torch.int16)
    t = torch.randint(0, 360_000, (streams, per), generator=g).sort(1).values.reshape(-1)
    p = torch.randint(0, 2, (events,), generator=g, dtype=torch.int8)
    offsets = torch.arange(streams + 1, dtype=torch.int64) * per
    batch = EventBatch(x, y, t, p, offsets, sensor_size=(240, 320), frame_ms=10.0,
                       t_start=torch.zeros(streams, dtype=torch.int64), n_frames=36)
    batch.sample_index()  # built once, as any earlier kernel would have (counted in the batch)
    bytes_ = sum(c.numel() * c.element_size() for c in (batch.x, batch.y, batch.t, batch.p))
    module = {
        "TES exact": lambda: et.TemporalEventShift(-2, 0.5),
        "TES binomial": lambda: et.TemporalEventShift(-2, 0.5, mode="binomial"),
        "FrameShift": lambda: et.FrameShift(-1),
        "RandomEventDrop(random)": lambda: et.RandomEventDrop(0.3, methods=("random",)),
    }[case]()
    params = module.make_params(batch.frame_shape, generator=torch.Generator().manual_seed(1))
    import warnings

    warnings.simplefilter("ignore")
    before = _status("VmRSS")
    with open("/proc/self/clear_refs", "w") as handle:
        handle.write("5")  # reset VmHWM to the current RSS
    out = module(batch, params=params)
    peak = _status("VmHWM")
    print(f"{case}|{batch.num_events}|{bytes_}|{peak - before}|{out.num_events}")


def main(argv: list[str] | None = None) -> list[tuple[str, float]]:
    parser = base_parser(__doc__.splitlines()[0], "tes-memory")
    parser.add_argument("--events", type=int, default=10_000_000)
    parser.add_argument("--streams", type=int, default=32)
    parser.add_argument("--child", default=None)
    args = parser.parse_args(argv)
    if args.child:
        child(args.child, args.events, args.streams)
        return []
    if args.quick:
        args.events, args.streams = 200_000, 8
    env = {k: v for k, v in child_env().items() if not k.startswith("MALLOC_")}
    rows = []
    lines = ["| kernel | events | batch MB | peak extra MB | x batch |", "|---|---|---|---|---|"]
    for case in CASES:
        result = subprocess.run(
            [sys.executable, __file__, "--child", case, "--events", str(args.events), "--streams", str(args.streams)],
            env=env, capture_output=True, text=True, check=True,
        )
        name, n, size, extra, _ = result.stdout.strip().splitlines()[-1].split("|")
        ratio = int(extra) / int(size)
        rows.append((name, ratio))
        lines.append(f"| {name} | {int(n):,} | {int(size) / 2**20:.0f} | {int(extra) / 2**20:.0f} | {ratio:.2f} |")
    publish("\n".join([
        "## Peak memory of the size-changing event kernels", "",
        "Each kernel in a fresh process; extra peak resident memory (`VmHWM` after `clear_refs`, output included) "
        "as a multiple of the batch's own bytes. The allocator's thresholds are *not* tuned here.", "",
        *environment_lines(), "", f"Command: `{command('library/tes_memory.py', argv)}`.", "", *lines]), args)
    return rows


if __name__ == "__main__":
    main()
