"""The protocol's run store: finished units on disk, keyed on everything that decides a result.

A unit's file (``OUT/runs/<settings key>/<unit>.json``) holds ``{"key": ..., "result": ...}``.
The folder's key is a hash of the protocol settings (:class:`~event_transforms.tactile.protocol.config.ProtocolConfig`),
the seeds, the reference model's constructor defaults and the package version, so a rerun
with other seeds or settings never reads another run's units (and a results table never
mixes seed sets). The file's key adds the scene, its methods and the data: for a built-in
scene its simulator settings and split seeds, for a folder of recordings the content hash of
its files and the layout settings. A unit is resumed only when the whole key matches; a file
whose key differs is recomputed, with the fields that differ named, and a file that cannot
be read (truncated, not JSON, not a unit) is named, deleted and recomputed — never a raw
traceback.
"""

from __future__ import annotations

__all__ = ["UNIT_FORMAT", "model_defaults", "folder_key", "folder_name", "data_key", "unit_key", "read_unit", "write_unit"]

import dataclasses
import hashlib
import inspect
import json
from pathlib import Path
from typing import Any

UNIT_FORMAT = 2


def _hash(value: Any, length: int = 10) -> str:
    return hashlib.sha256(json.dumps(value, sort_keys=True, default=repr).encode()).hexdigest()[:length]


def model_defaults() -> dict[str, Any]:
    """The reference model's constructor defaults (a changed default changes every result).

    Example:
        >>> model_defaults()["features"]
        'signed'
    """
    from .models import ForceRegressor

    parameters = inspect.signature(ForceRegressor.__init__).parameters.values()
    return {p.name: p.default for p in parameters if p.default is not inspect.Parameter.empty}


def _version() -> str:
    from .. import __version__

    return __version__


def folder_key(config: Any, seeds: list[int]) -> dict[str, Any]:
    """What every unit of a run shares: settings, seeds, model defaults, package version."""
    return {
        "format": UNIT_FORMAT,
        "package": _version(),
        "config": dataclasses.asdict(config),
        "seeds": [int(s) for s in seeds],
        "model_defaults": {k: list(v) if isinstance(v, tuple) else v for k, v in model_defaults().items()},
    }


def folder_name(config: Any, seeds: list[int]) -> str:
    """The run folder's name: a hash of :func:`folder_key`."""
    return _hash(folder_key(config, seeds))


def data_key(data: Any) -> str:
    """What decides a scene's data: a folder of recordings' content hash and layout settings
    (``data.dataset``), or a built-in scene's sessions, simulator version and split seeds; for
    other data sets given by hand, a hash of their items."""
    dataset = getattr(data, "dataset", None)
    if isinstance(dataset, dict) and "content_hash" in dataset:
        return _hash({"content": dataset["content_hash"], "settings": dataset.get("settings")}, 24)
    from . import datasets

    train = getattr(data, "train", None)
    if isinstance(train, datasets.TactileGrasps):
        scene = data.scene
        return _hash({
            "sessions": repr((scene.train, scene.deploy)), "simulator": datasets.SIMULATOR_VERSION,
            "cache_format": datasets._CACHE_FORMAT, "splits": datasets.SPLIT_SIZES, "seeds": datasets._SPLIT_SEED,
            "crop": train.crop_size, "pool": train.pool, "noise": None if data.noise_bank is None
            else list(data.noise_bank.shape),
            **({"data_seed_offset": train.seed} if train.seed else {}),  # a protocol seed's fresh data set
        }, 24)
    import torch

    from .baselines import stack_items

    digest = hashlib.sha256()
    for split in (data.train, data.holdout, data.val, data.test, data.noise_bank):
        if split is None:
            digest.update(b"none")
            continue
        tensors = [split] if isinstance(split, torch.Tensor) else list(stack_items(split))
        for tensor in tensors:
            digest.update(tensor.detach().cpu().contiguous().to(torch.float64).numpy().tobytes())
    return digest.hexdigest()[:24]


def unit_key(folder: dict[str, Any], scene: str, methods: tuple[str, ...], data: str) -> dict[str, Any]:
    """The key a unit's file must hold to be resumed."""
    return {**folder, "scene": scene, "methods": list(methods), "data": data}


def read_unit(path: Path, key: dict[str, Any]) -> tuple[dict[str, Any] | None, str | None]:
    """A unit's result when its file holds ``key``; else ``None`` and why (the file is
    deleted when it cannot be read). ``(None, None)``: no file."""
    if not path.exists():
        return None, None
    key = json.loads(json.dumps(key, default=repr))  # tuples as lists, as the file holds them
    try:
        stored = json.loads(path.read_text())
        if not isinstance(stored, dict) or not isinstance(stored.get("result"), dict) or "key" not in stored:
            raise ValueError("not a unit file of this version")
    except (OSError, ValueError) as error:
        path.unlink(missing_ok=True)
        return None, f"discarded the unreadable run file {path} ({type(error).__name__}: {error})"
    differ = sorted(k for k in set(key) | set(stored["key"]) if key.get(k) != stored["key"].get(k))
    if differ:
        return None, f"run file {path} was made with other {', '.join(differ)}"
    return stored["result"], None


def write_unit(path: Path, key: dict[str, Any], result: dict[str, Any]) -> None:
    """Write a unit's file atomically."""
    from ._files import write_json_atomic

    write_json_atomic(path, {"key": key, "result": result})
