"""The optical generator's verdict table, its data cost and its fidelity figure, in one command.

1. **Data.** Renders every render table the optical scenes need (cold: taxim; then cached) and
   simulates every split of every optical scene, timing both (render cost per table, event
   generation per grasp, the whole data set cold and cached).
2. **Fidelity** (no network, :func:`event_transforms.tactile.fidelity.fidelity`): the physics
   least-squares model fitted on the deployment's test grasps scores the training grasps
   after the size transforms (``optical-paper``, per training size) and after the rotation
   (``optical-orientation``), beside the same figure on the built-in ``paper`` and
   ``orientation`` scenes.
3. **Verdicts.** ``event-transforms reproduce --scenes optical-...`` (the unchanged protocol;
   ``--seeds``/``--steps`` for a reduced run) into ``--out``, whose ``results.json`` and
   ``report.md`` hold the optical verdict table.

4. **Side-by-side** (:func:`render`): each optical verdict beside the built-in generator's for the
   same role, the built-in column read from the committed built-in quick run
   (``benchmarks/tactile/reproduce_quick.md``, ``--builtin``), into ``--out/side_by_side.md`` and
   the ``optical-side-by-side`` sections of ``docs/results.md`` and ``benchmarks/tactile/optical.md``.

Run: ``EVENT_TRANSFORMS_CACHE=DIR python -m benchmarks.tactile.optical --out results-optical``
(``pip install 'event-transforms[optical]'`` first). ``--skip-protocol`` stops after 1 and 2;
``--render-only`` redoes 4 alone from the committed ``optical.md`` (after the built-in run is
regenerated), without data or training; ``--render-only --out results-optical`` rewrites the
whole optical page from that finished run first.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any


from event_transforms.tactile import datasets
from event_transforms.tactile.generators.optical import OpticalConfig, OpticalObject, render_table
from event_transforms.tactile.benchmark_scenes import OPTICAL_SCENES, get_scene
from event_transforms.tactile.simulation import draw_grasp

__all__ = ["prepare", "fidelity_figures", "side_by_side", "side_by_side_section", "render", "main"]

#: The optical scenes of the verdict table (each one a built-in scene's role).
ROLES = {
    "optical-control": "control", "optical-paper": "paper", "optical-orientation": "orientation",
    "optical-paper-membrane": "paper-membrane", "optical-paper-offset": "paper-offset", "optical-noise": "noise",
}
#: The scenes the script runs: the roles, and the hex head's orientation gap (no built-in twin).
RUN_SCENES = [*ROLES, "optical-orientation-hex"]


def _splits(scene_name: str) -> list[tuple[str, Any, range]]:
    scene = get_scene(scene_name)
    out = []
    for split, size in datasets.SPLIT_SIZES.items():
        session = scene.train if split in ("train", "holdout") else scene.deploy
        first = {"train": 0, "val": 10_000, "holdout": 30_000, "test": 40_000}[split]
        out.append((split, session, range(first, first + size)))
    return out


def prepare(scenes: Sequence[str], root: str | None) -> dict[str, Any]:
    """Render the tables, then build every split; timings in seconds."""
    optical = OpticalConfig()
    needed: set[tuple[str, float, float]] = set()
    sessions = {}
    for name in scenes:
        for split, session, seeds in _splits(name):
            sessions[(session, seeds.start)] = (session, seeds)
            kind = "hex" if session.generator == "optical-hex" else "cylinder"
            for k, seed in enumerate(seeds):
                grasp = draw_grasp(session.diameter(k), seed=seed, config=session.config)
                node = round(grasp.angle_deg / optical.angle_step_deg) * optical.angle_step_deg
                needed.add((kind, grasp.diameter_mm, node))
    start = time.perf_counter()
    for kind, diameter, node in sorted(needed):
        render_table(OpticalObject(kind, diameter), node, (180, 240), optical)
    tables_s = time.perf_counter() - start
    files = set(Path(str(datasets.default_cache_dir() if root is None else root)).glob("tactile-grasps-*.pt"))
    start = time.perf_counter()
    for name in scenes:
        for split in datasets.SPLIT_SIZES:
            datasets.TactileGrasps(split, root=root, scene=name)
    first_s = time.perf_counter() - start
    made = set(Path(str(datasets.default_cache_dir() if root is None else root)).glob("tactile-grasps-*.pt")) - files
    grasps = sum(seeds.stop - seeds.start for session, seeds in sessions.values())
    start = time.perf_counter()
    for name in scenes:
        for split in datasets.SPLIT_SIZES:
            datasets.TactileGrasps(split, root=root, scene=name)
    cached_s = time.perf_counter() - start
    return {"tables": len(needed), "tables_s": tables_s, "depth_nodes": int(optical.depths_mm.size),
            "distinct_splits": len(sessions), "grasps": grasps, "files_made": len(made),
            "datasets_first_s": first_s, "datasets_cached_s": cached_s}


def fidelity_figures(root: str | None) -> dict[str, dict[str, dict[str, float]]]:
    """scene -> training subset -> method -> MSE (N²), both generators."""
    from event_transforms.tactile.fidelity import SIZE_METHODS, fidelity
    from event_transforms.tactile.methods import parse_method

    results: dict[str, dict[str, dict[str, float]]] = {}
    for name in ("paper", "optical-paper", "orientation", "optical-orientation"):
        scene = get_scene(name)
        train = datasets.TactileGrasps("train", root=root, scene=name)
        val = datasets.TactileGrasps("val", root=root, scene=name)
        test = datasets.TactileGrasps("test", root=root, scene=name)
        metadata = [train.meta(i) for i in range(len(train))]
        if "orientation" in scene.gaps:
            methods: dict[str, Any] = {"none": None, "rot50": parse_method("rot50", scene=scene).build()}
            results[name] = {"15 mm": fidelity((test.frames, test.forces), (val.frames, val.forces),
                                               (train.frames, train.forces, metadata), methods)}
            continue
        methods = {"none": None, **{m: build(scene.target_size) for m, build in SIZE_METHODS.items()}}
        results[name] = {}
        for size in scene.train.diameters_mm:
            keep = [i for i, m in enumerate(metadata) if m["diameter_mm"] == size]
            subset = (train.frames[keep], train.forces[keep], [metadata[i] for i in keep])
            results[name][f"{size:g} mm"] = fidelity((test.frames, test.forces), (val.frames, val.forces), subset,
                                                      methods)
    return results


#: Built-in verdicts whose gap the method undoes exactly (the generator's inverse): the stretch
#: undoes the size gap, a frame shift the constant delays, the rotation the turned strip
#: (``inferred`` builds the same transform on those scenes).
BY_CONSTRUCTION = {
    ("paper", "stretch"), ("paper", "inferred"), ("paper-offset", "stretch"), ("paper-offset", "inferred"),
    ("paper-offset", "fs-1"), ("paper-membrane", "stretch"), ("paper-membrane", "inferred"),
    ("timing", "fs2"), ("timing", "inferred"), ("orientation", "rot50"), ("orientation", "inferred"),
}


def _word(verdict: Any) -> str:
    return "—" if verdict is None else f"{'**' if verdict.significant else ''}{verdict.mean:+.2f}" + (
        "**" if verdict.significant else "")


def side_by_side(builtin_text: str, optical_text: str) -> tuple[str, dict[str, int]]:
    """A markdown table of every verdict both runs have: built-in, optical, and the outcome
    (holds: same word, or significant both times with the same sign; flips: significant with opposite signs; unresolved: significant on the built-in
    generator only; new: significant on the optical one only), and the counts."""
    from event_transforms.tactile.report import summary_verdicts

    builtin = summary_verdicts(builtin_text)
    optical = {(ROLES.get(scene, scene), method, column): verdict
               for (scene, method, column), verdict in summary_verdicts(optical_text).items()}
    rows, counts = [], {"holds": 0, "flips": 0, "unresolved": 0, "new": 0}
    for key in sorted(set(builtin) & set(optical), key=lambda k: (list(ROLES.values()).index(k[0]), k[1], k[2])):
        a, b = builtin[key], optical[key]
        if a.word == b.word or (a.significant and b.significant and (a.mean > 0) == (b.mean > 0)):
            outcome = "holds"  # the same word, or resolved the same way under two labels (robust / resolved at 2x)
        elif a.significant and b.significant:
            outcome = "flips"
        elif a.significant:
            outcome = "unresolved"
        else:
            outcome = "new"
        counts[outcome] += 1
        scene, method, column = key
        mark = " (by construction)" if column == "vs none" and (scene, method) in BY_CONSTRUCTION else ""
        rows.append(f"| {scene} / optical-{scene} | {method} | {column} | {_word(a)}{mark} | {_word(b)} | {outcome} |")
    header = ["| scene (built-in / optical) | method | Δ | built-in | optical | outcome |", "|---|---|---|---|---|---|"]
    return "\n".join(header + rows), counts


ROOT = Path(__file__).resolve().parents[2]
#: The built-in generator's committed quick run: the side-by-side's built-in column.
BUILTIN_RUN = ROOT / "benchmarks" / "tactile" / "reproduce_quick.md"
#: The page this script writes: the optical run's cost, fidelity, side-by-side and whole output.
OPTICAL_PAGE = ROOT / "benchmarks" / "tactile" / "optical.md"
#: The results page and its section that holds the side-by-side.
RESULTS_PAGE = ROOT / "docs" / "results.md"
SECTION = "optical-side-by-side"


def produced_by(text: str) -> str:
    """The commit a protocol output names (``Produced by commit `...```), or ``"unknown"``."""
    import re

    found = re.search(r"Produced by commit `([0-9a-f]{7,40})`", text)
    return found.group(1) if found else "unknown"


def machine(text: str) -> str:
    """The protocol output's machine line (``One machine's numbers: ...``), its first sentence."""
    for line in text.splitlines():
        if line.startswith("One machine's numbers:"):
            return line.removeprefix("One machine's numbers:").split(". ")[0].strip()
    return "unknown"


def counts_sentence(counts: dict[str, int]) -> str:
    """The side-by-side's counts in words."""
    total = sum(counts.values())
    def verb(n: int, one: str, many: str) -> str:
        return f"{n} {one if n == 1 else many}"

    return (f"Of the {total} verdicts both runs have, **{verb(counts['holds'], 'holds', 'hold')}, "
            f"{verb(counts['flips'], 'flips', 'flip')}, {verb(counts['unresolved'], 'becomes', 'become')} unresolved "
            f"and {verb(counts['new'], 'is', 'are')} new**.")


def optical_run_text(page: str) -> str:
    """The optical run's whole ``results.md`` as :data:`OPTICAL_PAGE` quotes it."""
    marker = "## The optical run's output (`results.md`)"
    if marker not in page:
        raise ValueError(f"the optical page has no section {marker!r}")
    return page.split(marker, 1)[1].split(f"<!-- {SECTION}:start -->", 1)[0].strip() + "\n"


def protocol_of(text: str) -> str:
    """A protocol output's decision rules and data rule, in words (from its own header)."""
    from event_transforms.tactile.report import rules_version

    version = rules_version(text)
    rules = f"decision rules version {version}" if version else "decision rules version 1 (the page names none)"
    data = ("fresh data per seed" if "fresh per seed" in text or "new data sets from the simulator" in text
            else "every seed on the same data" if "with the data fixed" in text else "data rule not stated")
    return f"{rules}, {data}"


def side_by_side_section(builtin_text: str, optical_text: str, builtin_name: str) -> tuple[str, dict[str, int]]:
    """The ``optical-side-by-side`` section: where each column comes from, the table, the counts."""
    table, counts = side_by_side(builtin_text, optical_text)
    same = protocol_of(builtin_text) == protocol_of(optical_text)
    body = "\n".join([
        f"Built-in column: `{builtin_name}` (the built-in generator's quick run, produced by commit "
        f"`{produced_by(builtin_text)[:7]}`: {protocol_of(builtin_text)}). Optical column: "
        f"`benchmarks/tactile/optical.md` (produced by commit `{produced_by(optical_text)[:7]}`: "
        f"{protocol_of(optical_text)}; {machine(optical_text)})."
        + ("" if same else " **The two columns were judged under different protocols**: an outcome here compares "
           "two rule sets as well as two generators.")
        + " Re-rendered without training by `python -m benchmarks.tactile.optical --render-only`.",
        "", table, "", counts_sentence(counts) + " " + resolved_sentence(optical_text),
    ])
    return body, counts


def resolved_sentence(optical_text: str) -> str:
    """Every verdict the optical run resolves (its family interval excludes 0), the hex scene's included."""
    from event_transforms.tactile.report import summary_verdicts

    resolved = [f"{scene} / {method} {column} {verdict.mean:+.2f}"
                for (scene, method, column), verdict in sorted(summary_verdicts(optical_text).items())
                if verdict.significant]
    return ("Resolved on the optical generator (its own family intervals): " + "; ".join(resolved) + "."
            if resolved else "The optical run resolves no verdict.")


def render(out: Path | None = None, builtin_run: Path = BUILTIN_RUN) -> dict[str, int]:
    """Rewrite the side-by-side (the ``optical-side-by-side`` section of docs/results.md and of
    :data:`OPTICAL_PAGE`) without training; with ``out`` (a finished run: its ``results.md`` and
    ``optical_cost_fidelity.json``) the whole optical page first, else from the page's own copy
    of the run. The built-in column is ``builtin_run``'s."""
    from benchmarks._common import write_section

    if out is not None:
        run = json.loads((out / "optical_cost_fidelity.json").read_text())
        optical_text = (out / "results.md").read_text()
        protocol = run.get("protocol")
        when = (f"{protocol['seconds'] / 60:.0f} min of protocol (its `reproduce` call); load average "
                f"{protocol['load_start']:.1f} at its start and {protocol['load_end']:.1f} at its end on this "
                "machine's 2 cores" if protocol else "protocol time not recorded")
        fidelity_rows = [f"| {scene} | {subset} | " + " | ".join(f"{m} {v:.2f}" for m, v in scores.items()) + " |"
                         for scene, subsets in run["fidelity"].items() for subset, scores in subsets.items()]
        OPTICAL_PAGE.write_text("\n\n".join([
            "# The optical scenes' verdicts (`benchmarks/tactile/optical.py`)",
            f"Command: `EVENT_TRANSFORMS_CACHE=DIR {run.get('command', 'python -m benchmarks.tactile.optical')}`; "
            f"{when}.",
            "## Data cost (seconds; tables already on disk are not re-rendered)\n\n```json\n"
            + json.dumps(run["cost"], indent=1) + "\n```",
            "## Fidelity (physics least-squares model fitted on the deployment's test grasps, MSE N²)\n\n"
            "| scene | training grasps | scores |\n|---|---|---|\n" + "\n".join(fidelity_rows),
            "## Built-in vs optical verdicts\n\n<!-- optical-side-by-side:start -->\n<!-- optical-side-by-side:end -->",
            "## The optical run's output (`results.md`)\n\n" + optical_text,
        ]))
    optical_text = optical_run_text(OPTICAL_PAGE.read_text())
    name = str(builtin_run.resolve().relative_to(ROOT)) if builtin_run.resolve().is_relative_to(ROOT) else str(builtin_run)
    body, counts = side_by_side_section(builtin_run.read_text(), optical_text, name)
    write_section(SECTION, body, OPTICAL_PAGE)
    write_section(SECTION, body, RESULTS_PAGE)
    if out is not None:
        (out / "side_by_side.md").write_text(body + "\n")
    return counts


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=None, help="the protocol's output folder (default results-optical)")
    parser.add_argument("--root", default=None, help="data-set cache folder (default: the package's)")
    parser.add_argument("--scenes", nargs="+", default=RUN_SCENES, choices=list(OPTICAL_SCENES))
    parser.add_argument("--seeds", default=None, help="the protocol's seeds (default: its quick configuration)")
    parser.add_argument("--steps", default=None, help="the protocol's steps (default: its quick configuration)")
    parser.add_argument("--equal-time", action="store_true",
                        help="also the protocol's MSE at equal wall time (off here: it adds up to 57 %% to the run)")
    parser.add_argument("--skip-protocol", action="store_true", help="stop after the data and the fidelity figure")
    parser.add_argument("--render-only", action="store_true",
                        help="no data, no training: rewrite the side-by-side of docs/results.md and optical.md from "
                        "the committed optical.md (or, with --out given, the whole optical page from that run)")
    parser.add_argument("--builtin", type=Path, default=BUILTIN_RUN,
                        help="the built-in run whose verdicts are the side-by-side's built-in column "
                        "(default: benchmarks/tactile/reproduce_quick.md)")
    args = parser.parse_args(argv)
    if args.render_only:
        counts = render(args.out, args.builtin)
        print(json.dumps(counts))
        return {"counts": counts}
    args.out = args.out or Path("results-optical")
    args.out.mkdir(parents=True, exist_ok=True)
    cost = prepare(args.scenes, args.root)
    print(json.dumps(cost, indent=1), flush=True)
    figures = fidelity_figures(args.root)
    for scene, subsets in figures.items():
        for subset, scores in subsets.items():
            print(scene, subset, {m: round(v, 2) for m, v in scores.items()}, flush=True)
    run: dict[str, Any] = {"cost": cost, "fidelity": figures,
                           "command": "python -m benchmarks.tactile.optical "
                           + " ".join(argv if argv is not None else sys.argv[1:])}
    (args.out / "optical_cost_fidelity.json").write_text(json.dumps(run, indent=1))
    if not args.skip_protocol:
        import os

        from event_transforms.tactile.cli import main as cli_main

        command = ["reproduce", "--scenes", *args.scenes, "--out", str(args.out), "--no-plots",
                   "--equal-time" if args.equal_time else "--no-equal-time"]
        if args.root:
            command += ["--root", args.root]
        if args.seeds:
            command += ["--seeds", args.seeds]
        if args.steps:
            command += ["--steps", args.steps]
        load_start, start = os.getloadavg()[0], time.perf_counter()
        cli_main(command)
        run["protocol"] = {"seconds": time.perf_counter() - start, "load_start": load_start,
                           "load_end": os.getloadavg()[0]}
        (args.out / "optical_cost_fidelity.json").write_text(json.dumps(run, indent=1))
        counts = render(args.out, args.builtin)
        print((args.out / "side_by_side.md").read_text(), "\n", counts)
    return {"cost": cost, "fidelity": figures}


if __name__ == "__main__":
    main()
