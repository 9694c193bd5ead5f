"""Is taxim's render the same on every call? XLA's multi-threaded CPU kernels against the single-threaded ones.

One table of the optical generator (the 15 mm cylinder at 2.5°, every depth node, the default
grid) is rendered ``--renders`` times in one fresh process per mode, while ``--busy`` processes
spin beside it (the loaded machine on which version 3's tables came out different; on a quiet
machine the multi-threaded render too usually gives one image):

* **multi-threaded**: ``XLA_FLAGS=--xla_cpu_multi_thread_eigen=true`` (XLA's default; the
  optical generator leaves a user's flag alone and warns with ``RenderNotReproducibleWarning``);
* **single-threaded**: no ``XLA_FLAGS``, so :func:`~event_transforms.tactile.generators.optical.taxim_renderer`
  sets ``REPRODUCIBLE_XLA_FLAGS`` (``OPTICAL_VERSION`` 4).

Per mode: the distinct images among the renders, the largest difference from the first render
and the most RGB values that differ from it, and the median time of a render after the first
(which compiles). Replaces the ``optical-render`` section of ``benchmarks/tactile/RESULTS.md``.

    python -m benchmarks.tactile.optical_render [--renders 6] [--busy N] [--no-write]
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Sequence

from benchmarks._common import base_parser, command, environment_lines, markdown_table, publish

__all__ = ["render_in_child", "main"]

_CHILD = """
import hashlib, json, statistics, sys, time, warnings
import numpy as np
warnings.simplefilter("ignore")
from event_transforms.tactile.generators import optical
config = optical.OpticalConfig(render_scale=int(sys.argv[2]))
pressed = optical.height_map(optical.OpticalObject("cylinder", 15.0), 2.5, config)[None] - config.depths_mm[:, None, None]
render = optical.taxim_renderer(config)
images, seconds = [], []
for _ in range(int(sys.argv[1])):
    start = time.perf_counter()
    images.append(render(pressed))
    seconds.append(time.perf_counter() - start)
first = images[0]
print(json.dumps({
    "distinct": len({hashlib.sha256(np.ascontiguousarray(i).tobytes()).hexdigest() for i in images}),
    "max_diff": max(float(np.abs(i - first).max()) for i in images),
    "most_values": max(int((i != first).sum()) for i in images), "values": int(first.size),
    "maps": int(first.shape[0]), "seconds": statistics.median(seconds[1:]) if len(seconds) > 1 else seconds[0],
}))
"""

MODES = {"multi-threaded": "--xla_cpu_multi_thread_eigen=true", "single-threaded": None}


def render_in_child(xla_flags: str | None, renders: int, busy: int, render_scale: int = 2) -> dict[str, float]:
    """Render the table ``renders`` times in a fresh process with ``XLA_FLAGS=xla_flags`` (``None``: unset),
    ``busy`` spinning processes beside it; the child's figures (see the module docstring)."""
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    if xla_flags is not None:
        env["XLA_FLAGS"] = xla_flags
    spinning = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(busy)]
    try:
        out = subprocess.run([sys.executable, "-c", _CHILD, str(renders), str(render_scale)], env=env,
                             capture_output=True, text=True, check=True, timeout=1800).stdout
    finally:
        for process in spinning:
            process.kill()
            process.wait()
    return json.loads(out.strip().splitlines()[-1])


def main(argv: Sequence[str] | None = None) -> None:
    parser = base_parser(__doc__.splitlines()[0], "optical-render")
    parser.add_argument("--renders", type=int, default=6, help="renders per mode (default 6)")
    parser.add_argument("--busy", type=int, default=os.cpu_count() or 2,
                        help="spinning processes beside the render (default: one per core)")
    args = parser.parse_args(argv)
    scale = 8 if args.quick else 2
    renders = 2 if args.quick else args.renders
    rows = []
    for mode, flags in MODES.items():
        r = render_in_child(flags, renders, 0 if args.quick else args.busy, scale)
        rows.append([mode, f"{r['distinct']} of {renders}", f"{r['max_diff']:.3f}",
                     f"{r['most_values']:,} of {r['values']:,}", f"{r['seconds']:.2f}"])
    body = "\n".join([
        "## taxim's render: the same image on every call? (`optical_render.py`)", "",
        *environment_lines(("jax", "taxim")), "",
        f"Command: `{command('benchmarks.tactile.optical_render', argv)}`", "",
        f"One table ({r['maps']} depth maps of the 15 mm cylinder at 2.5°, render scale {scale}) rendered {renders} "
        f"times per mode in a fresh process, {0 if args.quick else args.busy} spinning process(es) beside it.", "",
        markdown_table(["XLA's CPU kernels", "distinct images", "largest difference from the first",
                        "most RGB values that differ", "s a render"], rows), "",
        "Multi-threaded, the image depends on the threads' timing; single-threaded (the optical generator's "
        "`REPRODUCIBLE_XLA_FLAGS`, `OPTICAL_VERSION` 4) it does not.",
    ])
    publish(body, args)


if __name__ == "__main__":
    main()
