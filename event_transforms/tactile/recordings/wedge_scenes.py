"""The natural splits of the GelSight Wedge grasps as named scenes: one ``recordings.csv`` each.

A folder converted from the GelSight Wedge layout (``event-transforms convert FOLDER --out DIR``,
:func:`~event_transforms.tactile.recordings.video.convert_video_folder`) holds one recording per
grasp with ``object``, ``session`` (the day) and ``trial`` columns. The splits nobody here
designed (the data's README) become scenes: ``DIR/scenes/<name>/recordings.csv``, the same rows
with their ``role`` (and ``split``) set and their paths pointing back into ``DIR``, so that
``event-transforms reproduce --data DIR/scenes/<name>`` runs the protocol on each and no event
file is copied.

==================  =========================================================================
scene               roles
==================  =========================================================================
``hardness-balls``  train ``purple_ball_hardest`` + ``orange_ball_softest``, deploy
                    ``green_ball_softer``, on the days that have all three (2023-12-06,
                    2023-12-16): the paper's interpolation, the middle hardness unseen
``hardness-foam``   train ``blue_foam_brick_harder`` + ``yellow_foam_brick_softest``, deploy
                    ``red_foam_brick_softer`` (2023-12-16)
``session``         train 2023-12-06, deploy 2023-12-16, on the objects of the same name on
                    both days (golf ball and the three balls; 2023-12-06's ``foam_brick`` has
                    no namesake on 2023-12-16, which holds three foam bricks, so it is left out)
``shape``           train the spheres (golf ball and the three balls, both days), deploy the
                    other shapes (``bolt``, ``rose_eraser``, ``rigid_strawberry``)
``control``         2023-12-16, every object: trials 0 and 1 train, trial 2 deploys (the same
                    objects, the same day: no gap by construction)
==================  =========================================================================

Splits (the ``split`` column; every row gets one where the rule below gives it, else the
layout's rule): within the training role, the last trial of each object and day with at least
two training trials is the hold-out of the stopping rule; within the deployment role, the first
trial of each object and day with at least two deployment trials validates and the rest test.
Where no deployment group has two trials (``control``) the layout's rule applies: the first
fifth of the deployment recordings (in table order) validate.
"""

from __future__ import annotations

__all__ = ["WEDGE_SCENES", "wedge_scene_rows", "write_wedge_scenes"]

import csv
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .._files import atomic_write

_BALLS = ("purple_ball_hardest", "orange_ball_softest", "green_ball_softer")
_SPHERES = ("golf_ball", "purple_ball_hardest", "orange_ball_softest", "green_ball_softer")
_FOAM = ("blue_foam_brick_harder", "yellow_foam_brick_softest", "red_foam_brick_softer")
_SHAPES = ("bolt", "rose_eraser", "rigid_strawberry")
_DAY1, _DAY2 = "2023-12-06", "2023-12-16"


def _hardness_balls(obj: str, day: str, trial: str) -> str | None:
    if day not in (_DAY1, _DAY2) or obj not in _BALLS:
        return None
    return "deploy" if obj == "green_ball_softer" else "train"


def _hardness_foam(obj: str, day: str, trial: str) -> str | None:
    if day != _DAY2 or obj not in _FOAM:
        return None
    return "deploy" if obj == "red_foam_brick_softer" else "train"


def _session(obj: str, day: str, trial: str) -> str | None:
    if obj not in _SPHERES:
        return None
    return {_DAY1: "train", _DAY2: "deploy"}.get(day)


def _shape(obj: str, day: str, trial: str) -> str | None:
    if obj in _SPHERES:
        return "train"
    return "deploy" if obj in _SHAPES else None


def _control(obj: str, day: str, trial: str) -> str | None:
    if day != _DAY2 or trial not in ("0", "1", "2"):
        return None
    return "deploy" if trial == "2" else "train"


#: scene name -> (the role of a grasp from its object, day and trial, or ``None``: not in the
#: scene; what the scene asks, in words).
WEDGE_SCENES: dict[str, tuple[Callable[[str, str, str], str | None], str]] = {
    "hardness-balls": (_hardness_balls, "hardest + softest ball -> the middle one (2023-12-06, 2023-12-16)"),
    "hardness-foam": (_hardness_foam, "hardest + softest foam brick -> the middle one (2023-12-16)"),
    "session": (_session, "2023-12-06 -> 2023-12-16, the golf ball and the three balls"),
    "shape": (_shape, "spheres -> bolt, rose eraser, strawberry"),
    "control": (_control, "2023-12-16, trials 0-1 -> trial 2 of the same objects (no gap)"),
}


def _trial_key(row: dict[str, str]) -> tuple[int, str]:
    trial = row.get("trial", "")
    return (int(trial), trial) if trial.isdigit() else (0, trial)


def wedge_scene_rows(rows: list[dict[str, str]], scene: str) -> list[dict[str, str]]:
    """The rows of one scene: each grasp of ``rows`` the scene holds, its ``role`` and ``split`` set.

    Args:
        rows: rows of a converted folder's ``recordings.csv`` (``object``, ``session`` and
            ``trial`` columns).
        scene: a name of :data:`WEDGE_SCENES`.

    Returns:
        The scene's rows in the order of ``rows`` (paths unchanged), with ``role`` and ``split``.

    Raises:
        ValueError: an unknown scene; rows without ``object``, ``session`` or ``trial``.

    Example:
        >>> rows = [{"events": f"events/{o}{t}.npz", "object": o, "session": "2023-12-16", "trial": t}
        ...         for o in ("blue_foam_brick_harder", "red_foam_brick_softer") for t in "012"]
        >>> [(r["object"][:4], r["trial"], r["role"], r["split"]) for r in wedge_scene_rows(rows, "hardness-foam")]
        [('blue', '0', 'train', 'train'), ('blue', '1', 'train', 'train'), ('blue', '2', 'train', 'holdout'), ('red_', '0', 'deploy', 'val'), ('red_', '1', 'deploy', 'test'), ('red_', '2', 'deploy', 'test')]
    """
    if scene not in WEDGE_SCENES:
        raise ValueError(f"scene must be one of {sorted(WEDGE_SCENES)}, got {scene!r}")
    rule = WEDGE_SCENES[scene][0]
    out: list[dict[str, str]] = []
    for number, row in enumerate(rows, start=2):
        missing = [c for c in ("object", "session", "trial") if c not in row]
        if missing:
            raise ValueError(f"recordings.csv row {number}: no {missing} column(s); a scene of the GelSight Wedge "
                             "grasps needs the object, session and trial columns `convert` writes")
        role = rule(row["object"], row["session"], row["trial"])
        if role is not None:
            out.append({**row, "role": role, "split": ""})
    groups: dict[tuple[str, str, str], list[dict[str, str]]] = {}
    for row in out:
        groups.setdefault((row["role"], row["object"], row["session"]), []).append(row)
    deploy_grouped = any(len(g) >= 2 for (role, _, _), g in groups.items() if role == "deploy")
    for (role, _, _), group in groups.items():
        ordered = sorted(group, key=_trial_key)
        if role == "train" and len(ordered) >= 2:
            for row in ordered:
                row["split"] = "train"
            ordered[-1]["split"] = "holdout"
        elif role == "deploy" and deploy_grouped:
            for row in ordered:
                row["split"] = "test"
            ordered[0]["split"] = "val"
    return out


def write_wedge_scenes(root: str | os.PathLike[str], *, log: Any = None) -> dict[str, Path]:
    """Write ``root/scenes/<name>/recordings.csv`` for every scene of :data:`WEDGE_SCENES` the folder holds.

    A scene is written when it has at least 3 training and 2 labelled deployment recordings
    (the protocol's limits); the others are named as skipped. Paths point back into ``root``
    (``../../events/...``), so nothing is copied; a table written before is replaced.

    Args:
        root: a folder converted from the GelSight Wedge layout (its ``recordings.csv`` has
            ``object``, ``session`` and ``trial`` columns).
        log: called with one line per scene written or skipped.

    Returns:
        scene name -> the scene's folder (for ``reproduce --data``).

    Example:
        >>> import tempfile
        >>> root = Path(tempfile.mkdtemp())
        >>> rows = ["events/e%d.npz,force/f%d.csv,train,%s,2023-12-16,%d" % (k, k, o, t)
        ...         for k, (o, t) in enumerate((o, t) for o in _FOAM for t in range(3))]
        >>> _ = (root / "recordings.csv").write_text("events,force,role,object,session,trial\\n" + "\\n".join(rows))
        >>> sorted(write_wedge_scenes(root))
        ['control', 'hardness-foam']
        >>> (root / "scenes" / "hardness-foam" / "recordings.csv").read_text().splitlines()[1]
        '../../events/e0.npz,../../force/f0.csv,train,blue_foam_brick_harder,2023-12-16,0,train'
    """
    root = Path(root)
    table = root / "recordings.csv"
    if not table.is_file():
        raise ValueError(f"{root} holds no recordings.csv; convert the grasps first (event-transforms convert)")
    with open(table, newline="") as handle:
        reader = csv.DictReader(handle)
        header = [*(reader.fieldnames or [])]
        rows = list(reader)
    if "split" not in header:
        header.append("split")
    written: dict[str, Path] = {}
    for name, (_, what) in WEDGE_SCENES.items():
        scene = wedge_scene_rows(rows, name)
        train = sum(r["role"] == "train" for r in scene)
        deploy = sum(r["role"] == "deploy" and bool(r.get("force")) for r in scene)
        if train < 3 or deploy < 2:
            if log:
                log(f"scene {name}: not written ({train} training and {deploy} labelled deployment recordings; "
                    "the protocol needs at least 3 and 2)")
            continue
        folder = root / "scenes" / name
        folder.mkdir(parents=True, exist_ok=True)
        for row in scene:  # paths relative to the scene's folder
            for column in ("events", "force", "width"):
                if row.get(column):
                    row[column] = f"../../{row[column]}"
        with atomic_write(folder / "recordings.csv", "w") as handle:
            writer = csv.DictWriter(handle, fieldnames=header, lineterminator="\n", extrasaction="ignore", restval="")
            writer.writeheader()
            writer.writerows(scene)
        written[name] = folder
        if log:
            splits = {s: sum(r["split"] == s for r in scene) for s in ("train", "holdout", "val", "test")}
            log(f"scene {name} ({what}): {train} training and {deploy} deployment recordings "
                f"({', '.join(f'{v} {k}' for k, v in splits.items() if v)}) -> {folder}")
    return written
