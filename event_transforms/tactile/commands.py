"""The bodies of the ``event-transforms`` commands; :mod:`~event_transforms.tactile.cli` parses
the arguments and calls them (one function per command, named after it), and the two run
presets :data:`QUICK` and :data:`FULL` that ``reproduce`` reads. Figures are drawn by
:mod:`~event_transforms.tactile.figures`. Nothing heavy is imported until a command runs.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .cli_data import recording_settings

if TYPE_CHECKING:  # pragma: no cover
    from .protocol.config import ProtocolConfig

__all__ = [
    "QUICK", "FULL", "reproduce", "simulate", "show", "show_scene", "infer_scene", "train", "predict", "compare",
    "recording_settings", "load_recordings", "writable", "ItemProgress",
]

#: The quick configuration (default): stated in the output of every run. The model
#: (issue 17): one ConvLSTM layer of 4 channels on 5 x 5 cells (``input_pool=14``), the
#: signed OFF - ON input with its running sum, mean readout and global inputs (the
#: ``ForceRegressor`` defaults); 300 steps. Measured on validation data, 4 seeds: the
#: control's MSE is 0.81 / 0.34 / 0.31 N² after 150 / 300 / 600 steps (paper: 2.19 / 1.49 /
#: 1.57).
QUICK: dict[str, Any] = {
    # the control, the paper's split, its clock-offset and membrane-lag variants and two
    # other gapped scenes (those that exist); the rest (ablations included) run with --full
    "scenes": ("control", "paper", "paper-offset", "paper-membrane", "timing", "orientation"),
    "seeds": 8,
    "steps": 300,
    "lr": 1e-2,
    "hidden_channels": (4,),
    "input_pool": 14,
    "batch_size": 8,
    "eval_every": 50,
    "threads": 1,
    "jobs": 2,
    # MSE at equal wall time too: every method retrained for the steps its online augmentation
    # leaves in none's wall time (a second column and figure)
    "equal_time": True,
}


def quick_config() -> ProtocolConfig:
    """The quick configuration, as ``event-transforms reproduce`` builds it without options
    (the configuration :data:`~event_transforms.tactile.protocol.costs.QUICK_COST_TABLE` was measured for).

    Example:
        >>> quick_config().steps > 0
        True
    """
    from .protocol.config import ProtocolConfig

    return ProtocolConfig(steps=QUICK["steps"], batch_size=QUICK["batch_size"], lr=QUICK["lr"],
                          eval_every=QUICK["eval_every"], hidden_channels=tuple(QUICK["hidden_channels"]),
                          input_pool=QUICK["input_pool"])
#: The full configuration (``--full``): the paper's 10 seeds and layer sizes.
FULL: dict[str, Any] = {
    "scenes": None,  # every scene
    "seeds": 10,
    "steps": 1500,
    "lr": 1e-2,
    "hidden_channels": (8, 16),
    "input_pool": 4,
    "batch_size": 8,
    "eval_every": 100,
    "threads": 1,
    "jobs": None,  # one per core
    "equal_time": False,  # --equal-time adds it (it retrains every method once more)
}


def load_recordings(args: argparse.Namespace, deployment: bool = True) -> Any:
    """The folder's SceneData, with one line saying what was read and how (``deployment=False``:
    a folder of training recordings only, for ``train``)."""
    from .recordings import load_recording_data

    if not args.data.is_dir():
        raise ValueError(f"--data {str(args.data)!r} is not a folder")
    root = getattr(args, "root", None)
    binning = ItemProgress("binned ", "binning recordings", "recordings")
    try:
        data = load_recording_data(args.data, recording_settings(args),
                                   cache=None if root is None else root / "recordings", log=binning,
                                   deployment=deployment)
    finally:
        summary = binning.close()
    if summary:
        _print(summary)
    d = data.dataset
    _print(f"data: {d['folder']} ({d['files']} files, content hash {d['content_hash'][:16]}); recordings per split "
           f"{d['recordings']}, windows {d['windows']} of {args.frames} frames of {args.frame_ms:g} ms (stride "
           f"{d['settings']['stride']}); crop {tuple(d['crop'])} ({d['crop_source']}), pool {args.pool}; "
           f"{d['left_out_frames']} frames after the last whole window left out")
    return data


def _print(*args: Any) -> None:
    print(*args, flush=True)


class ItemProgress:
    """A ``log`` callable for a loop that reports every item: lines starting with ``prefix``
    advance one progress bar (tqdm, shown on a terminal) instead of printing a line each, and
    :meth:`close` returns one summary line (``None`` when no item was reported); other lines
    are printed as they come.

    Example:
        >>> log = ItemProgress("binned ", "binning", "recordings", bar=False)
        >>> for name in ("a", "b", "c"):
        ...     log(f"binned {name} in 0.0 s")
        >>> log("crop: (0, 0, 10, 10)")
        crop: (0, 0, 10, 10)
        >>> log.close().split(" in ")[0]
        'binning: 3 recordings'
    """

    def __init__(self, prefix: str, description: str, unit: str, *, bar: bool | None = None) -> None:
        self.prefix, self.description, self.unit = prefix, description, unit
        self.count, self.start = 0, time.perf_counter()
        self._show = bar
        self._bar: Any = None

    def __call__(self, line: str) -> None:
        if not line.startswith(self.prefix):
            _print(line)
            return
        if self._bar is None and self._show is not False:
            from tqdm.auto import tqdm

            # disable=None: a bar on a terminal only; in a log file, just the summary line
            self._bar = tqdm(desc=self.description, unit=f" {self.unit}", disable=None if self._show is None else False,
                             leave=False, dynamic_ncols=True)
        if self._bar is not None:
            self._bar.update(1)
        self.count += 1

    def close(self) -> str | None:
        """Close the bar; one line saying how many items took how long, or ``None``."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        if not self.count:
            return None
        return f"{self.description}: {self.count} {self.unit} in {time.perf_counter() - self.start:.1f} s"


def writable(path: Path | None, flag: str) -> None:
    """Refuse a folder that cannot be created or written, before any work starts."""
    if path is None:
        return
    import tempfile

    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError as error:
        raise ValueError(f"{flag} {str(path)!r} is not a writable folder ({error.strerror or error})") from None


def _quiet_log(line: str) -> None:
    """``reproduce --quiet``'s log: every line but the per-unit ones (``[rank r] unit k/N ...``) and
    the legend of the progress lines."""
    if not (line.startswith("[rank ") or line.startswith("progress lines:")):
        _print(line)


def _default_batch(default: int, data: Any) -> int:
    """The default batch size, or a folder's training windows where they are fewer (said in one line)."""
    if len(data.train) >= default:
        return default
    _print(f"batch size {len(data.train)}: the folder's {len(data.train)} training windows are fewer than the default "
           f"{default} (--batch-size sets it, at most the training windows)")
    return max(1, len(data.train))


def _data_methods(scene: Any) -> list[str]:
    """A folder of recordings runs none and the policies it can build (no oracle: the gaps are inferred)."""
    from .methods import EXTRA_METHODS, parse_method

    kept: list[str] = ["none"]
    left_out: dict[str, list[str]] = {}
    for name in EXTRA_METHODS:
        try:
            parse_method(name, scene=scene)
        except ValueError as error:  # grouped by reason: "stretch, inferred (... has none)"
            left_out.setdefault(str(error).replace(f"method {name!r} ", ""), []).append(name)
        else:
            kept.append(name)
    if left_out:
        _print(f"default rows: {', '.join(kept)}; left out, as the scene cannot build them: "
               + "; ".join(f"{', '.join(names)} ({reason})" for reason, names in left_out.items())
               + (". With no gap inferred there is nothing to compare: only none (and none-local, the network without "
                  "global inputs) is trained (--methods names other rows, e.g. --methods none rot50 fs2)"
                  if set(kept) <= {"none", "none-local"} else ""))
    return kept


#: The README's main job measured against the plan's training estimate (commit e25223d, the quiet 2-core
#: AMD EPYC, an empty data cache): it took 12.1 min where ``--plan`` said 4.3 min of training; the plan's
#: whole-run figure scales its training estimate by that ratio.
_QUICK_RUN_WALL_MIN, _QUICK_RUN_ESTIMATE_MIN = 12.1, 4.3
_WALL_PER_TRAINING_ESTIMATE = _QUICK_RUN_WALL_MIN / _QUICK_RUN_ESTIMATE_MIN


def _plan_time(plan: dict[str, Any], chosen: dict[str, Any], scenes: list[str], seeds: list[int], config: Any,
               jobs: int, shared: int, curve: int) -> str:
    """The run's time from the committed cost table, where it covers the run: the member-steps
    trained (shared members not counted, in the main phase and the budget check) × the
    table's seconds per member-step, over ``jobs``."""
    from .protocol.costs import QUICK_COST_TABLE, cost_key, equal_cost_steps, load_cost_table

    table = load_cost_table(QUICK_COST_TABLE) if QUICK_COST_TABLE.exists() else None
    if table is None or table["config"] != cost_key(config) or not table.get("ensemble_s_per_member_step"):
        return "time: no committed cost table covers this configuration (the run measures its own)"
    ratios = table["ratios"]
    equal = sum(equal_cost_steps(config.steps, ratios.get(s, {}).get(m, 1.0)) for s in scenes for m in chosen[s]
                if m != "none" and equal_cost_steps(config.steps, ratios.get(s, {}).get(m, 1.0)) < config.steps)
    main = plan.get("trained_member_steps", plan["member_steps"] - shared * len(seeds) * config.steps)
    trained = main + plan.get("budget_trained_member_steps", plan["budget_member_steps"]) + equal * len(seeds) + curve
    seconds = trained * float(table["ensemble_s_per_member_step"]) / max(jobs, 1)
    return (f"time: about {seconds / 60:.0f} min of training for at most {trained:,} member-steps at "
            f"{table['ensemble_s_per_member_step'] * 1e3:.1f} ms per member-step over {jobs} job(s) (the cost table's "
            "32-member ensemble, measured "
            f"on {table.get('environment', {}).get('cpu_model', 'an unnamed CPU')}); the whole run about "
            f"{seconds * _WALL_PER_TRAINING_ESTIMATE / 60:.0f} min (the README's run took {_QUICK_RUN_WALL_MIN} min "
            f"where this line said {_QUICK_RUN_ESTIMATE_MIN} min of training: the data, evaluation, baselines, the "
            "timing phase and ensembles smaller than 32 members are the rest)")


def reproduce(args: argparse.Namespace) -> int:
    writable(args.out, "--out")
    writable(args.root, "--root")
    if args.data is not None and args.scenes:
        raise ValueError("give --data DIR or --scenes, not both")
    import torch

    from .distributed import join_from_env
    from .protocol.config import ProtocolConfig
    from .protocol.plan import choose_methods, plan_run
    from .protocol.run import run_protocol
    from .protocol.rules import RULES
    from .report import format_report
    from .benchmark_scenes import SCENES

    base = FULL if args.full else QUICK
    device = args.device
    if device == "auto":
        device = "cuda" if torch.cuda.is_available() else "cpu"
    if device == "cuda" and not torch.cuda.is_available():
        raise SystemExit("--device cuda: no CUDA device is available")
    threads = args.threads or base["threads"]
    distributed = join_from_env(device)
    jobs = args.jobs or base["jobs"] or (torch.cuda.device_count() if device == "cuda" else os.cpu_count() or 1)
    if device == "cuda" and not distributed:
        jobs = 1  # one process drives the GPU; ensembles fill it
    seeds = args.seeds or list(range(base["seeds"]))
    given = None
    if args.data is not None:
        recorded = load_recordings(args)
        given = {recorded.scene.name: recorded}
    config = ProtocolConfig(
        steps=args.steps or base["steps"],
        batch_size=args.batch_size or (base["batch_size"] if given is None else
                                       _default_batch(base["batch_size"], next(iter(given.values())))),
        lr=args.lr or base["lr"],
        eval_every=base["eval_every"],
        hidden_channels=tuple(args.hidden_channels or base["hidden_channels"]),
        input_pool=args.input_pool or base["input_pool"],
        cumulative=not args.no_cumulative,
        fixed=not args.online,
        copies=args.copies,
    )
    scenes = args.scenes or (list(SCENES) if base["scenes"] is None else [s for s in base["scenes"] if s in SCENES])
    methods: Any = None if args.methods is None else list(args.methods)
    if given is not None:
        scenes = list(given)
        if methods is None:
            methods = {scenes[0]: _data_methods(given[scenes[0]].scene)}
        _print(f"inferred scene: gaps {list(given[scenes[0]].scene.gaps) or 'none'} "
               f"(from {given[scenes[0]].dataset['inferred_from']})")
    chosen = choose_methods(scenes, methods, full=args.full, data=given)
    if args.group is None:  # fresh data per seed: a unit is one seed's, so a scene's methods share it
        args.group = "scene" if given is None and config.resample == "fresh" else "method"
    if given is not None:  # every limit of the data before any training (built-in scenes: in run_protocol)
        from .protocol.limits import check_run_limits

        for note in check_run_limits(given, chosen, config, cli=True):
            _print(note)
    equal_time = base["equal_time"] if args.equal_time is None else args.equal_time
    plan = plan_run(scenes, chosen, seeds, config, group=args.group, budget_check=not args.no_budget_check,
                    data=given, equal_time=equal_time)
    if args.plan:
        _print(f"plan: scenes {scenes}, {len(seeds)} seeds, {config.steps} steps per run")
        for scene, names in chosen.items():
            _print(f"  {scene}: {', '.join(names)}")
        from .copies import load_scene_data
        from .protocol.plan import count_phases, phase_units, plan_line
        from .protocol.shared import plan_sharing

        data = given or {s: load_scene_data(s, None if args.root is None else str(args.root)) for s in scenes}
        fresh = given is None and config.resample == "fresh"
        # fresh data per seed: each seed's units, shared as the base data set's (the same sessions)
        phases = phase_units(scenes, chosen, args.group, {s: data for s in seeds} if fresh else data,
                             plan["budget_check_scenes"], equal_time, given, seeds)
        sharing = phases.sharing
        count_phases(plan, phases, seeds, config)
        _print(plan_line(plan, config) + " (× the seconds per member-step a unit reports); budget check on "
               f"{plan['budget_check_scenes']}")
        if equal_time:
            none_only = {s: ("none",) for s in scenes}
            trained_none = len(scenes) - plan_sharing(none_only, data).shared
            curve = trained_none * len(seeds) * round(1.5 * config.steps)
            _print(f"equal cost: at most {plan['equal_time_member_steps_max']:,} more member-steps (every method but "
                   f"none retrained for floor(steps / its cost ratio) steps from the cost table, at most "
                   f"{config.steps}); cost curve: none at {round(1.5 * config.steps)} steps on {trained_none} "
                   f"training set(s), {curve:,} member-steps (none at {2 * config.steps} is the budget check's); "
                   f"total at most {plan['total_member_steps'] + plan['equal_time_member_steps_max'] + curve:,}")
            _print(_plan_time(plan, chosen, scenes, seeds, config, jobs, sharing.shared, curve))
        if fresh:
            files = {getattr(split, "path", None): len(split) for d in data.values()
                     for split in (d.train, d.holdout, d.val, d.test) if split is not None}
            grasps = sum(n for path, n in files.items() if path is not None)
            _print(f"data: fresh per seed: each of the {len(seeds)} seeds draws its own {grasps} grasps "
                   f"({len(files)} distinct splits of the scenes' sessions), about {grasps * 0.011:.0f} s per seed "
                   "on one thread to simulate (0.011 s per grasp), once: they are cached under "
                   "$EVENT_TRANSFORMS_CACHE")
        elif given is not None:
            _print("data: a folder of recordings: no new data can be drawn, so each seed reads its own bootstrap "
                   "resample by recording (the intervals cover resamples of these recordings, not new ones)")
        return 0
    rank = int(os.environ.get("RANK", "0")) if distributed else 0
    say = _print if rank == 0 else (lambda *a: None)
    label = "full" if args.full else "quick"
    say(
        f"event-transforms reproduce: {label} configuration — seeds {seeds}, {config.steps} optimiser steps "
        f"per run (the same for every method), one-cycle lr peak {config.lr:g}, clip {config.clip:g}, "
        f"batch {config.batch_size}, ConvLSTM channels {config.hidden_channels}, input pool "
        f"{config.input_pool}, {'cumulative' if config.cumulative else 'per-frame'} input, the weights with the "
        f"lowest hold-out MSE (checked every {config.eval_every} steps), "
        f"{'on-the-fly' if args.online else 'fixed'} synthetic copies; device {device}, "
        + (f"{os.environ.get('WORLD_SIZE')} torchrun ranks" if distributed else f"{jobs} job(s)")
        + f", {threads} thread(s) each"
    )
    cost_table = args.cost_table
    if cost_table is None and equal_time and given is None:
        from .protocol.costs import QUICK_COST_TABLE, cost_key, load_cost_table

        committed = load_cost_table(QUICK_COST_TABLE) if QUICK_COST_TABLE.exists() else None
        if committed is not None and committed["config"] == cost_key(config) and all(
                m in committed["ratios"].get(s, {}) for s in scenes for m in chosen[s]):
            cost_table = QUICK_COST_TABLE
    start = time.perf_counter()
    quiet = getattr(args, "quiet", False)
    results = run_protocol(
        scenes, seeds, args.out, config=config, methods=chosen, full=args.full,
        root=None if args.root is None else str(args.root), jobs=1 if distributed else jobs,
        device=device, threads=threads, group=args.group, log=_quiet_log if quiet else _print,
        progress=False if quiet else None, budget_check=not args.no_budget_check,
        data=given, equal_time=equal_time, cost_table=cost_table, cli=True,
    )
    if not results:  # a torchrun rank other than 0
        return 0
    say()
    if given is not None:
        counts = next(iter(given.values())).dataset["recordings"]
        say(f"Results on {results['data']}: the intervals rest on {counts['test']} test recordings "
            f"({counts['val']} validation, {counts['train']} training, {counts['holdout']} hold-out).")
    say(f"Results on {'your recordings' if given is not None else 'synthetic data'} ({label} configuration; test MSE in N² over all frames, mean ± sample sd "
        f"over {len(seeds)} paired seeds (the same initial weights and the same original items at the same "
        f"steps); Δ vs none with its paired t-interval adjusted for the scene's family (Bonferroni: level "
        f"1 − {RULES.alpha:g}/m for m non-duplicate methods; decision rules version {RULES.version}), ** where that "
        "interval excludes 0; a row bit-identical per seed "
        "to an earlier one reads '= row X' and is not in the family; the exact Wilcoxon p is shown only where "
        f"it can reach {RULES.alpha:g} (its floor with {len(seeds)} seeds is m × {2 / 2 ** len(seeds):.3g}); beside it the "
        "unpaired (Welch) interval and r, the correlation of none's and the method's per-seed MSEs; policy rows "
        "also Δ vs the scene's matched row; kept step: the median step whose weights the "
                "stopping rule kept (in brackets the share of members that stopped before the step cap); time "
        "columns: see the scene tables"
        + ("; equal wall time: each method retrained for the steps its online augmentation leaves in the wall "
           "time of one none model (its Δ vs none's main run, a family of its own)" if equal_time else "")
        + "; baselines are fitted on the same training data):")
    say(format_report(results))
    if not args.no_plots:
        from .figures import plot_results

        for path in plot_results(results, args.out):
            say(f"wrote {path}")
    say(f"wrote {args.out / 'results.json'} and {args.out / 'results.md'} in {time.perf_counter() - start:.1f} s")
    return 0


def simulate(args: argparse.Namespace) -> int:
    writable(args.root, "--root")
    from .copies import load_scene_data
    from .benchmark_scenes import SCENES, get_scene

    root = None if args.root is None else str(args.root)
    if args.export is not None:
        from .recordings import export_scene

        scene = get_scene(args.scene)  # the name first, before any simulation
        writable(args.export, "--export")
        start = time.perf_counter()
        table = export_scene(scene, args.export, log=_print)
        _print(f"wrote {table} and the events and force files of scene {scene.name!r} in "
               f"{time.perf_counter() - start:.1f} s; run: event-transforms reproduce --data {args.export}")
        return 0
    from tqdm.auto import tqdm

    total = time.perf_counter()
    sizes: dict[str, list[str]] = {}  # one line per distinct set of sizes, not one per scene
    for name in tqdm(SCENES, desc="simulating scenes", unit=" scenes", disable=None, leave=False, dynamic_ncols=True):
        data = load_scene_data(name, root)
        bank = "none" if data.noise_bank is None else tuple(data.noise_bank.shape)
        described = (f"{len(data.train)} train, {len(data.val)} val, {len(data.test)} test sequences, "
                     f"static-scene bank {bank}")
        sizes.setdefault(described, []).append(name)
    for described, names in sizes.items():
        _print(f"scenes {', '.join(names)}: {described}")
    _print(f"all {len(SCENES)} scenes in {time.perf_counter() - total:.1f} s (root: {root or 'package cache'})")
    return 0


def show_scene(args: argparse.Namespace) -> int:
    """One labelled figure per scene from ``--count`` freshly simulated grasps per session
    (not the cached splits: a picture needs a few grasps, not 168)."""
    import torch

    from .. import viz
    from .benchmark_scenes import SCENES, get_scene

    names = [get_scene(args.scene).name] if args.scene else list(SCENES)
    if args.rows > args.count:
        raise ValueError(f"--rows {args.rows} draws more grasps than --count {args.count} simulates per session; "
                         f"pass --count {args.rows} or more")
    writable(args.out, "--out")
    args.out.mkdir(parents=True, exist_ok=True)
    simulated: dict = {}  # scenes share sessions (most train on the base session): simulate each once

    def grasps(session, seed):
        if (session, seed) not in simulated:
            recordings = session.simulate(session.grasps(args.count, seed=seed))
            simulated[session, seed] = torch.stack([r.frames(crop=r.contact_crop((140, 150)), pool=2) for r in recordings])
        return simulated[session, seed]

    for name in names:
        start = time.perf_counter()
        scene = get_scene(name)
        sessions = [grasps(scene.train, 0), grasps(scene.deploy, 10_000)]
        path = args.out / f"scene_{name}.png"
        gaps = [
            f"{factor} ({'; '.join(f'{k} {a} → {b}' for k, (a, b) in settings.items())})"
            for factor, settings in scene.gap_sizes().items()
        ]
        viz.plot_scene(
            sessions[0], sessions[1], path, title=f"{name}: {scene.description}", gaps=gaps,
            frame_ms=scene.train.config.frame_ms, rows=args.rows, every=args.every, upscale=args.upscale,
        )
        _print(f"wrote {path} ({args.rows} training rows above {args.rows} deployment rows, histograms of "
               f"{args.count} grasps per session; {time.perf_counter() - start:.1f} s)")
    return 0


def show(args: argparse.Namespace) -> int:
    import torch

    from .. import viz
    from . import datasets
    from .methods import parse_method

    method = parse_method(args.method, scene=args.scene)  # names first, before any simulation
    name = f"{args.method.replace(':', '_')}.png"
    out = args.out or Path(name)
    if out.is_dir():  # an existing folder: the picture goes inside it, under the method's name
        out = out / name
    elif not out.suffix:
        raise ValueError(f"--out {str(out)!r} must name a .png file or an existing folder")
    writable(args.root, "--root")
    writable(out.parent, "--out")
    root = None if args.root is None else str(args.root)
    train = datasets.TactileGrasps(split="train", root=root, scene=args.scene)
    if not 0 <= args.index < len(train):
        raise SystemExit(f"--index must lie in [0, {len(train) - 1}], got {args.index}")
    frames, _, meta = train[args.index]
    bank = datasets.noise_bank(config=train.scene.deploy.config) if method.needs_noise_bank else None
    transform = method.build(bank)
    generator = torch.Generator().manual_seed(args.seed)
    with torch.no_grad():
        after = frames if transform is None else transform(frames, generator=generator, metadata=meta)
    title = f"{args.method} on {args.scene} training grasp {args.index} ({meta['diameter_mm']:g} mm)"
    viz.plot_transform(frames, after, out, frame_ms=train.config.frame_ms, count=args.count,
                       title=title, upscale=args.upscale)
    _print(f"wrote {out}")
    return 0


def _format_evidence(scene: Any) -> list[str]:
    """One line per factor: training and deployment estimates, difference, z and the verdict."""
    lines = []
    evidence = scene.evidence or {}
    for factor in ("timing", "orientation", "noise"):
        e = evidence.get(factor)
        if e:
            # the verdict as infer_scene states it: gap, no gap, or not resolvable (with what would resolve it)
            said = evidence.get("verdicts", {}).get(factor, "gap" if e["gap"] else "no gap")
            verdict = "GAP" + said[3:] if said.startswith("gap") else said  # "gap; labelled lags not ..." too
            z = "z n/a" if math.isnan(e["z"]) else f"z {e['z']:+.1f}"
            if e.get("source") == "labelled recordings":  # lags from events against the force labels
                lines.append(
                    f"  {factor}: lag_ms from {e['train']['n']} training and {e['deploy']['n']} deployment labelled "
                    f"recordings (events against force): median train {e['train']['median']:.3g} ± "
                    f"{e['train']['se']:.2g} (spread {e['train']['spread']:.2g}), deploy {e['deploy']['median']:.3g} ± "
                    f"{e['deploy']['se']:.2g} (spread {e['deploy']['spread']:.2g}), difference "
                    f"{e['difference']:+.3g} ({z}): {verdict}")
                e = e["onset"]  # the unlabeled statistic, reported beside it
                verdict = "reported, not used"
                z = "z n/a" if math.isnan(e["z"]) else f"z {e['z']:+.1f}"
            lines.append(f"  {factor}: {e['statistic']} train {e['train']['mean']:.3g} ± {e['train']['se']:.2g} "
                         f"(n {e['train']['n']}), deploy {e['deploy']['mean']:.3g} ± {e['deploy']['se']:.2g} "
                         f"(n {e['deploy']['n']}), difference {e['difference']:+.3g} ({z}): {verdict}")
            hot = e.get("hot_pixels")
            if hot:  # the noise gap's second trace, with its own standard error
                hot_z = "z n/a" if math.isnan(hot["z"]) else f"z {hot['z']:+.1f}"
                lines.append(f"    hot pixels per window: train {hot['train']['mean']:.3g} ± {hot['train']['se']:.2g}, "
                             f"deploy {hot['deploy']['mean']:.3g} ± {hot['deploy']['se']:.2g} ({hot_z}): "
                             f"{'GAP' if hot['gap'] else 'no gap' if hot['resolvable'] else 'not resolvable (standard error 0)'}")
    size = evidence.get("size")
    if size:
        width = size["width_px"]
        lines.append(f"  size: sizes train {size['train_sizes']}, deploy {size['deploy_sizes']} (from diameter_mm): "
                     f"{'GAP' if size['gap'] else 'no gap'}; contact width ratio deploy/train {width['ratio']:.3f} "
                     f"± {width['ratio_se']:.3f} (reported, not used: size is not identifiable from frames)")
    return lines


def infer_scene(args: argparse.Namespace) -> int:
    data = load_recordings(args)
    scene = data.scene.inferred
    _print(f"inferred from {data.dataset['inferred_from']}: gaps {list(scene.gaps) or 'none'}")
    for line in _format_evidence(scene):
        _print(line)
    policy = scene.policy("independent")
    _print(f"policy (independent): {[type(t).__name__ for t in policy.transforms] or 'identity'}")
    return 0


def train(args: argparse.Namespace) -> int:
    import torch

    from .deployment import train_model

    writable(args.out.parent if str(args.out.parent) else Path("."), "--out")
    torch.set_num_threads(args.threads)
    data = load_recordings(args, deployment=False)
    if args.policy == "inferred" and not data.dataset["windows"]["val"] + data.dataset["windows"]["unlabeled"]:
        raise ValueError("--policy inferred needs deployment recordings (role deploy) to infer the gaps from")
    if args.batch_size is None:
        args.batch_size = _default_batch(QUICK["batch_size"], data)
    if args.batch_size > len(data.train):
        raise ValueError(f"--batch-size {args.batch_size} is more than the {len(data.train)} training windows "
                         f"({data.dataset['recordings']['train']} recordings): a step would repeat windows within "
                         f"its batch; give --batch-size {len(data.train)} or fewer")
    from .protocol.limits import holdout_note

    note = holdout_note(data)
    if note:
        _print(note)
    start = time.perf_counter()
    model, summary = train_model(
        data, args.policy, steps=args.steps, batch_size=args.batch_size, lr=args.lr,
        eval_every=min(QUICK["eval_every"], args.steps), hidden_channels=tuple(args.hidden_channels),
        input_pool=args.input_pool, seed=args.seed,
    )
    settings = data.dataset["settings"]
    preprocessing = {**settings, "force_offset_n": summary["force_offset"], "force_scale_n": summary["force_scale"],
                     "policy": args.policy, "data": {k: data.dataset[k] for k in ("folder", "content_hash", "files")}}
    model.save(args.out, preprocessing=preprocessing)
    kept = (f"kept step {summary['kept_step']}, hold-out MSE {summary['holdout_mse']:.3g} N²" if not note else
            f"final weights kept: no hold-out ({data.dataset['recordings']['train']} training recordings)")
    _print(f"trained with policy {args.policy!r} for {args.steps} steps in {time.perf_counter() - start:.1f} s "
           f"({kept}); " + (
               f"validation MSE {summary['val_mse']:.3g} N², test MSE {summary['test_mse']:.3g} N² on "
               f"{data.dataset['recordings']['test']} test recordings" if len(data.test) else
               "not scored: the folder holds no labelled deployment recordings"))
    _print(f"wrote {args.out} (weights, model settings, preprocessing: frame_ms {settings['frame_ms']:g}, crop "
           f"{tuple(settings['crop'])}, pool {settings['pool']}, force scaling; package version)")
    return 0


def predict(args: argparse.Namespace) -> int:
    import torch

    from .deployment import predict_stream
    from .models import ForceRegressor

    torch.set_num_threads(args.threads)
    writable(args.out.parent if str(args.out.parent) else Path("."), "--out")
    model = ForceRegressor.load(_checkpoint(args.model))
    start = time.perf_counter()
    stats = predict_stream(model, args.events, args.out, sensor_size=args.sensor_size, time_unit=args.time_unit,
                           columns=args.columns, log=_print)
    _print(f"wrote {args.out}: {stats['frames']} frames from {stats['events']:,} events in "
           f"{time.perf_counter() - start:.1f} s; step latency p50 {stats['p50_ms']:.3f} ms, p99 "
           f"{stats['p99_ms']:.3f} ms per frame")
    return 0


def _checkpoint(path: Path) -> Path:
    """``path`` if it can be a checkpoint (a torch zip file), else the error naming what it is."""
    import zipfile

    if path.is_file() and not zipfile.is_zipfile(path):
        kind = f"a {path.suffix} file" if path.suffix else "not a zip file"
        raise ValueError(f"MODEL {str(path)!r} is not a checkpoint written by `event-transforms train` ({kind}); "
                         "the command is `predict MODEL EVENTS`, the model first")
    return path


def compare(args: argparse.Namespace) -> int:
    from .report import compare_verdicts, format_verdict_comparison, rules_version, run_verdicts

    verdicts, versions = [], []
    for name in ("a", "b"):
        path = getattr(args, name)
        if not path.is_file():
            raise ValueError(f"{name}: no such file {str(path)!r}")
        text = path.read_text()
        try:
            verdicts.append(run_verdicts(text))
        except ValueError as error:
            raise ValueError(f"{name} ({path}): {error}") from None
        versions.append(rules_version(text))
    first, second = verdicts
    if versions[0] != versions[1]:  # different rules judge the same numbers differently: say so first
        named = [f"version {v}" if v else "no version (written before the rules carried one)" for v in versions]
        warning = (f"warning: the two runs were judged by different decision rules ({args.a}: {named[0]}; "
                   f"{args.b}: {named[1]}): a verdict that moved may have moved with the rules, not the runs")
        if getattr(args, "same_rules", False):
            raise ValueError(warning.removeprefix("warning: ") + " (--same-rules refuses to compare them)")
        print(warning, file=sys.stderr)
        _print(warning + "\n")
    _print(format_verdict_comparison(first, second, names=(str(args.a), str(args.b))))
    return 1 if compare_verdicts(first, second)["reversed"] else 0
