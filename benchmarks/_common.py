"""Shared helpers for the benchmark scripts: timing, environment header, tables, RESULTS.md.

Every script times its subject against a baseline measured in the same run
(``torch.utils.benchmark``, median and interquartile range) and prints ratios, not bare
times. Each script owns one section of the ``RESULTS.md`` beside it (``benchmarks/library/`` or
``benchmarks/tactile/``), delimited by
``<!-- NAME:start -->`` and ``<!-- NAME:end -->``; :func:`write_section` replaces only that
section, so scripts run in any order without clobbering each other.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import re
import statistics
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
import torch.utils.benchmark as tbench

from event_transforms._profiling import HOST_SYNC_OPS, OpCounts, count_ops, synthetic_frames

__all__ = [
    "RESULTS",
    "Timing",
    "time_call",
    "time_repeated",
    "time_interleaved",
    "environment",
    "environment_lines",
    "allocator_suffix",
    "markdown_table",
    "write_section",
    "base_parser",
    "synthetic_frames",
    "fmt_ms",
    "fmt_ratio",
    "loglog_slope",
    "apply_threads",
    "command",
    "child_env",
    "results_of",
    "count_ops",
    "OpCounts",
    "HOST_SYNC_OPS",
]

#: The benchmark folders; a script's results file is the ``RESULTS.md`` of its folder.
FOLDERS = Path(__file__).resolve().parent
RESULTS = FOLDERS / "library" / "RESULTS.md"


def child_env(extra: dict[str, str] | None = None) -> dict[str, str]:
    """The environment for a script run as a child process (``python path/to/script.py``): the
    repository first on ``PYTHONPATH``, so ``benchmarks._common`` imports, plus ``extra``."""
    path = os.pathsep.join(p for p in (str(FOLDERS.parent), os.environ.get("PYTHONPATH", "")) if p)
    return {**os.environ, "PYTHONPATH": path, **(extra or {})}


def results_of(script: str | os.PathLike) -> Path:
    """The ``RESULTS.md`` beside a script (``benchmarks/library/`` or ``benchmarks/tactile/``)."""
    return Path(script).resolve().with_name("RESULTS.md")


@dataclass(frozen=True)
class Timing:
    """One timing: median and interquartile range in seconds, and how many runs."""

    median: float
    iqr: float
    runs: int

    def ratio(self, baseline: Timing) -> float:
        return self.median / baseline.median


def time_call(fn: Callable[[], Any], *, min_run_time: float = 0.5, label: str = "") -> Timing:
    """Time ``fn()`` with ``torch.utils.benchmark.Timer.blocked_autorange``.

    ``blocked_autorange`` picks a block size so that each measurement lasts long enough,
    then repeats blocks for at least ``min_run_time`` seconds; we report the median and
    IQR of the per-call times over the blocks.
    """
    timer = tbench.Timer(
        stmt="fn()",
        globals={"fn": fn},
        label=label,
        num_threads=torch.get_num_threads(),
    )
    fn()  # warm up (lazy imports, allocator)
    m = timer.blocked_autorange(min_run_time=min_run_time)
    return Timing(median=m.median, iqr=m.iqr, runs=len(m.times))


def time_interleaved(
    cases: dict[str, Callable[[], Any]],
    *,
    baseline: str,
    rounds: int = 5,
    min_run_time: float = 0.2,
    progress: bool = True,
) -> tuple[dict[str, Timing], dict[str, float]]:
    """Time every case in ``rounds`` interleaved rounds; returns timings and ratios to ``baseline``.

    On a shared machine the speed drifts over a run; timing all cases once per round
    (each with ``blocked_autorange``) and taking, per case, the median over rounds of its
    ratio to the baseline measured in the same round keeps drift out of the ratios.
    The returned :class:`Timing` pools every block of every round (median and IQR).
    """
    if baseline not in cases:
        raise ValueError(f"baseline must be one of the cases, got {baseline!r}")
    times: dict[str, list[float]] = {name: [] for name in cases}
    per_round: dict[str, list[float]] = {name: [] for name in cases}
    for fn in cases.values():
        fn()  # warm up
    for r in range(rounds):
        for name, fn in cases.items():
            m = tbench.Timer(stmt="fn()", globals={"fn": fn}, num_threads=torch.get_num_threads()).blocked_autorange(
                min_run_time=min_run_time
            )
            times[name].extend(m.times)
            per_round[name].append(m.median)
        if progress:
            print(f"  round {r + 1}/{rounds} done", file=sys.stderr, flush=True)
    timings = {}
    for name, ts in times.items():
        q = statistics.quantiles(ts, n=4) if len(ts) >= 2 else [ts[0]] * 3
        timings[name] = Timing(median=statistics.median(ts), iqr=q[2] - q[0], runs=len(ts))
    ratios = {
        name: statistics.median(a / b for a, b in zip(per_round[name], per_round[baseline])) for name in cases
    }
    return timings, ratios


def time_repeated(fn: Callable[[], Any], *, repeats: int = 5, warmup: int = 1) -> Timing:
    """Median and IQR of ``repeats`` single calls (for calls too slow to block, e.g. a loader epoch)."""
    import time

    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    times.sort()
    q = statistics.quantiles(times, n=4) if len(times) >= 2 else [times[0]] * 3
    return Timing(median=statistics.median(times), iqr=q[2] - q[0], runs=len(times))


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _version(module: str) -> str:
    try:
        mod = __import__(module)
    except Exception:  # noqa: BLE001 - optional peers may fail to import in many ways
        return "not installed"
    return getattr(mod, "__version__", "unknown")


def environment(extra_modules: Sequence[str] = ()) -> dict[str, str]:
    """Versions and hardware, for the header of every results table."""
    import event_transforms

    info = {
        "date": datetime.datetime.now().strftime("%Y-%m-%d %H:%M"),
        "python": platform.python_version(),
        "event_transforms": event_transforms.__version__,
        "torch": torch.__version__,
    }
    for module in ("torchvision", "kornia", "numpy", *extra_modules):
        info[module] = _version(module)
    info["cpu"] = _cpu_model()
    info["logical cores"] = str(os.cpu_count())
    info["torch threads"] = str(torch.get_num_threads())
    info["cuda"] = torch.cuda.get_device_name(0) if torch.cuda.is_available() else "none (CPU run)"
    # glibc returns allocations above MALLOC_MMAP_THRESHOLD_ (at most 32 MiB by default) to
    # the OS on free, so every new 48 MB batch is page-faulted in again: record the setting.
    malloc = {k: v for k, v in os.environ.items() if k.startswith("MALLOC_") or k == "LD_PRELOAD"}
    info["allocator"] = ", ".join(f"{k}={v}" for k, v in sorted(malloc.items())) or "glibc defaults"
    return info


def allocator_suffix() -> str:
    """`` (MALLOC_* tuned)`` when glibc's allocator settings are changed, else empty (for titles)."""
    tuned = sorted(k for k in os.environ if k.startswith("MALLOC_"))
    return f" ({', '.join(tuned)} set)" if tuned else ""


def environment_lines(extra_modules: Sequence[str] = ()) -> list[str]:
    env = environment(extra_modules)
    return ["Environment: " + "; ".join(f"{k} {v}" for k, v in env.items())]


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """A GitHub-flavoured Markdown table; right-aligns every column but the first."""
    cells = [[str(c) for c in header]] + [[str(c) for c in row] for row in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    lines = []
    for n, row in enumerate(cells):
        padded = [row[0].ljust(widths[0])] + [c.rjust(w) for c, w in zip(row[1:], widths[1:])]
        lines.append("| " + " | ".join(padded) + " |")
        if n == 0:
            rule = ["-" * widths[0]] + ["-" * (w - 1) + ":" for w in widths[1:]]
            lines.append("| " + " | ".join(rule) + " |")
    return "\n".join(lines)


def write_section(name: str, body: str, path: str | os.PathLike | None = None) -> Path:
    """Replace (or append) the section ``name`` of the results file with ``body``.

    Only the text between ``<!-- name:start -->`` and ``<!-- name:end -->`` changes; the
    file is written atomically (temporary file + rename).
    """
    if not re.fullmatch(r"[A-Za-z0-9_-]+", name):
        raise ValueError(f"name must be letters, digits, '_' or '-', got {name!r}")
    path = Path(path) if path is not None else RESULTS
    start, end = f"<!-- {name}:start -->", f"<!-- {name}:end -->"
    block = f"{start}\n{body.strip()}\n{end}"
    text = path.read_text() if path.exists() else "# Benchmark results\n\nWritten by the scripts of this folder; each owns one section.\n"
    pattern = re.compile(re.escape(start) + r".*?" + re.escape(end), re.DOTALL)
    if pattern.search(text):
        text = pattern.sub(lambda _: block, text, count=1)
    else:
        text = text.rstrip("\n") + "\n\n" + block + "\n"
    tmp = path.with_name(path.name + f".tmp{os.getpid()}")
    tmp.write_text(text)
    os.replace(tmp, path)
    return path


def publish(body: str, args: argparse.Namespace) -> None:
    """Print a script's section and, unless ``--no-write``, write it into RESULTS.md."""
    print(body)
    if not args.no_write:
        write_section(args.section, body, args.results)


def base_parser(description: str, section: str, script: str | os.PathLike | None = None) -> argparse.ArgumentParser:
    """The options every script takes; ``--results`` defaults to the ``RESULTS.md`` beside
    ``script`` (the caller's ``__file__``; found on the call stack when not given)."""
    if script is None:
        import inspect

        script = inspect.stack()[1].filename
    results = results_of(script)
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--section", default=section, help="section of the results file (default: %(default)s)")
    parser.add_argument("--quick", action="store_true", help="tiny sizes and short timings (smoke test)")
    parser.add_argument("--results", default=str(results), help="Markdown file to update (default: %(default)s)")
    parser.add_argument("--no-write", action="store_true", help="print only; do not update the results file")
    parser.add_argument("--threads", type=int, default=None, help="torch.set_num_threads (default: torch's)")
    return parser


def apply_threads(threads: int | None) -> None:
    if threads is not None:
        torch.set_num_threads(threads)


def fmt_ms(seconds: float) -> str:
    if seconds >= 1.0:
        return f"{seconds:.2f} s"
    if seconds >= 1e-3:
        return f"{seconds * 1e3:.2f} ms"
    return f"{seconds * 1e6:.1f} µs"


def fmt_ratio(value: float) -> str:
    return f"{value:.2f}×" if value < 100 else f"{value:.0f}×"


def loglog_slope(xs: Sequence[float], ys: Sequence[float]) -> float:
    """Least-squares slope of log(y) against log(x)."""
    import math

    lx = [math.log(x) for x in xs]
    ly = [math.log(y) for y in ys]
    mx, my = sum(lx) / len(lx), sum(ly) / len(ly)
    var = sum((a - mx) ** 2 for a in lx)
    if var == 0:
        return float("nan")
    return sum((a - mx) * (b - my) for a, b in zip(lx, ly)) / var


def command(script: str, argv: Sequence[str] | None) -> str:
    """The command line that reproduces this run, for the results section."""
    env = " ".join(f"{k}={v}" for k, v in sorted(os.environ.items()) if k.startswith("MALLOC_"))
    args = " ".join(argv if argv is not None else sys.argv[1:])
    return " ".join(p for p in (env, f"python -m benchmarks.{script.removesuffix('.py').replace('/', '.')}", args) if p)
