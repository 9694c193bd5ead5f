"""The committed cost table of the README's quick configuration, measured again in one command.

Each method's cost per training step relative to ``none`` (one step with the method's online
augmentation over one plain step; interleaved, median of 5 rounds:
:func:`event_transforms.tactile.protocol.costs.measure_costs`) for every scene and method of the
quick run, written to ``event_transforms/tactile/protocol/cost_table_quick.json`` with the machine
and the commit it was measured on. ``event-transforms reproduce`` reads it for the equal-cost
column, so that column's step counts are the same on every machine and under any load.

Run: ``MALLOC_MMAP_THRESHOLD_=1073741824 MALLOC_TRIM_THRESHOLD_=1073741824 python benchmarks/tactile/cost_table.py``
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Sequence
from pathlib import Path

from event_transforms.tactile.commands import QUICK, quick_config
from event_transforms.tactile.copies import load_scene_data
from event_transforms.tactile.protocol.costs import QUICK_COST_TABLE, measure_costs
from event_transforms.tactile.protocol.plan import choose_methods
from event_transforms.tactile.benchmark_scenes import SCENES

__all__ = ["main"]


def main(argv: Sequence[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=QUICK_COST_TABLE, help="where the table goes")
    parser.add_argument("--repeats", type=int, default=5, help="interleaved rounds (the median is kept)")
    parser.add_argument("--root", default=None, help="data-set cache folder")
    args = parser.parse_args(argv)
    scenes = [s for s in QUICK["scenes"] if s in SCENES]
    chosen = choose_methods(scenes)
    data = {s: load_scene_data(s, args.root) for s in scenes}
    tick = time.perf_counter()
    table = measure_costs(scenes, chosen, data, quick_config(), repeats=args.repeats)
    table["measured_s"] = time.perf_counter() - tick
    args.out.write_text(json.dumps(table, indent=1, sort_keys=True) + "\n")
    print(f"wrote {args.out}: {sum(len(v) for v in table['ratios'].values())} ratios in {table['measured_s']:.0f} s "
          f"({table['environment'].get('cpu_model')}, commit {str(table['commit'])[:7]})")
    return table


if __name__ == "__main__":
    main()
