"""Train once: members keyed by what their training reads, shared by every scene that has them.

A member (method × seed) of a protocol run reads the training and hold-out sets, the built
augmentation policy (the transform its copies get, and how many copies), the noise bank if
the policy draws from it, the configuration and its seed. Two scenes whose members read the
same things train the same weights, bit for bit (members of an ensemble are independent:
grouped convolutions, per-member clipping and Adam state). So a run keys every (scene,
method) by :func:`member_key` and trains each key once, in the unit of the first scene that
has it (its *owner*); the weights are then scored on the validation and test sets of every
other scene that shares the key (its *borrowers*). Policies are compared as built, not by
name: ``inferred`` reads each scene's deployment frames and builds another policy per scene.

Example:
    >>> import torch
    >>> from event_transforms.tactile.copies import SceneData
    >>> from event_transforms.tactile.benchmark_scenes import get_scene
    >>> g = torch.Generator().manual_seed(0)
    >>> def items(n):
    ...     frames = torch.poisson(torch.full((n, 4, 2, 6, 6), 0.5), generator=g)
    ...     return [(f, f.sum((1, 2, 3)), {"diameter_mm": 15.0}) for f in frames]
    >>> train, holdout = items(4), items(2)
    >>> a = SceneData(get_scene("control"), train, items(2), items(2), holdout=holdout)
    >>> b = SceneData(get_scene("timing"), train, items(2), items(2), holdout=holdout)
    >>> sharing = plan_sharing({"control": ("none",), "timing": ("none", "fs2")}, {"control": a, "timing": b})
    >>> sharing.owner[("timing", "none")], sharing.owned
    (('control', 'none'), {'control': ('none',), 'timing': ('fs2',)})
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import torch

from ..copies import SceneData
from ..methods import parse_method

__all__ = ["Sharing", "plan_sharing", "member_key", "training_key", "content_key", "collect", "records_by_method",
           "seed_values", "SHARED_SEPARATOR"]

#: Borrowed results live in the owner unit's file under ``"<scene>::<method>"``.
SHARED_SEPARATOR = "::"


def _update_tensor(digest: Any, value: torch.Tensor) -> None:
    value = value.detach().cpu().contiguous()
    digest.update(f"{value.dtype}{tuple(value.shape)}".encode())
    digest.update(value.numpy().tobytes())


def training_key(data: SceneData) -> str:
    """A content hash of what every member of ``data``'s scene trains on: the training and
    hold-out items (frames, forces and metadata), not the validation or test sets."""
    return content_key(data.train, data.holdout)


def content_key(*splits: Any) -> str:
    """A content hash of the items (frames, forces and metadata) of ``splits`` (``None``: no split)."""
    digest = hashlib.sha256()
    for split in splits:
        if split is None:
            digest.update(b"no split")
            continue
        digest.update(f"{len(split)} items".encode())
        for index in range(len(split)):
            item = split[index]
            _update_tensor(digest, torch.as_tensor(item[0]))
            _update_tensor(digest, torch.as_tensor(item[1]))
            digest.update(repr(sorted(item[2].items()) if len(item) > 2 and isinstance(item[2], Mapping)
                               else None).encode())
    return digest.hexdigest()[:24]


def member_key(data: SceneData, method_name: str, training: str | None = None) -> str:
    """What a member of ``method_name`` on ``data``'s scene reads besides its seed and the
    configuration (which every member of a run phase shares): the training data, the built
    policy (its transform's full ``repr``, settings included) and its number of copies, and
    the noise bank's content when the policy draws from it. ``training``: ``data``'s
    :func:`training_key`, if known."""
    method = parse_method(method_name, scene=data.scene)
    transform = method.build(data.noise_bank)
    digest = hashlib.sha256()
    digest.update((training or training_key(data)).encode())
    digest.update(repr(transform).encode())
    digest.update(f"copies={method.copies if transform is not None else 0}".encode())
    if transform is not None and method.needs_noise_bank and data.noise_bank is not None:
        _update_tensor(digest, data.noise_bank)
    if method.model:  # another model (none-local: no global inputs)
        digest.update(repr(method.model).encode())
    if method.reads_deployment_labels:  # with-labels trains on the deployment's validation items too
        digest.update(content_key(data.val if data.labelled is None else data.labelled).encode())
    return digest.hexdigest()[:24]


@dataclass
class Sharing:
    """Which (scene, method) trains and which borrows its members.

    ``owner[(scene, method)]`` is the (scene, method) whose unit trains that member (itself
    for an owner); ``owned[scene]`` the methods the scene's own units train; ``borrowers``
    the (scene, method) pairs each owner is also scored for.
    """

    owner: dict[tuple[str, str], tuple[str, str]]
    owned: dict[str, tuple[str, ...]]
    borrowers: dict[tuple[str, str], list[tuple[str, str]]] = field(default_factory=dict)

    @property
    def shared(self) -> int:
        """How many (scene, method) pairs borrow instead of training."""
        return sum(len(b) for b in self.borrowers.values())

    def also(self, scene: str, methods: Sequence[str]) -> tuple[tuple[str, str, str], ...]:
        """``(owner method, borrowing scene, its method)`` for the members of a unit of ``scene``."""
        return tuple((m, s, n) for m in methods for s, n in self.borrowers.get((scene, m), ()))


def plan_sharing(chosen: Mapping[str, Sequence[str]], data: Mapping[str, SceneData]) -> Sharing:
    """Key every (scene, method) of ``chosen`` (scenes in order) and name an owner per key: the
    first scene that has it. Keys are computed here, once, before any training."""
    first: dict[str, tuple[str, str]] = {}
    owner: dict[tuple[str, str], tuple[str, str]] = {}
    borrowers: dict[tuple[str, str], list[tuple[str, str]]] = {}
    for scene, methods in chosen.items():
        training = training_key(data[scene])
        for method in methods:
            key = member_key(data[scene], method, training)
            owner[(scene, method)] = first.setdefault(key, (scene, method))
            if owner[(scene, method)] != (scene, method):
                borrowers.setdefault(owner[(scene, method)], []).append((scene, method))
    owned = {scene: tuple(m for m in methods if owner[(scene, m)] == (scene, m)) for scene, methods in chosen.items()}
    return Sharing(owner, {s: ms for s, ms in owned.items() if ms}, borrowers)


def collect(unit_scenes: Mapping[str, str], results: Mapping[str, Mapping[str, list]],
            scene: str, names: Sequence[str]) -> dict[str, list[dict[str, Any]]]:
    """Per method of ``scene`` (in ``names``), its records, sorted by seed: from the scene's own
    units, or borrowed from the owner unit (``unit_scenes``: unit slug -> its scene)."""
    per_method: dict[str, list[dict[str, Any]]] = {}
    for slug, unit_scene in unit_scenes.items():
        for name, records in results[slug].items():
            if SHARED_SEPARATOR in name:
                other, method = name.split(SHARED_SEPARATOR, 1)
                if other == scene:
                    per_method.setdefault(method, []).extend(records)
            elif unit_scene == scene:
                per_method.setdefault(name, []).extend(records)
    return {m: sorted(per_method[m], key=lambda r: r["seed"]) for m in names if m in per_method}


def records_by_method(units: Sequence[Any], results: Mapping[str, Mapping[str, list]], scene: str,
                      names: Sequence[str]) -> dict[str, list[dict[str, Any]]]:
    """Per method of ``scene``, its records by seed: trained by the scene's own ``units`` (each
    with a ``slug`` and a ``scene``: :class:`~event_transforms.tactile.protocol.plan.Unit`), or
    borrowed from the unit that trained the same member for another scene (:func:`collect`)."""
    return collect({u.slug: u.scene for u in units}, results, scene, names)


def seed_values(runs: Sequence[Mapping[str, Any]]) -> dict[str, list]:
    """``{"seeds", "test_mse"}`` of one method's records, by seed.

    Example:
        >>> seed_values([{"seed": 1, "test_mse": 2.0}, {"seed": 0, "test_mse": 3.0}])
        {'seeds': [0, 1], 'test_mse': [3.0, 2.0]}
    """
    runs = sorted(runs, key=lambda r: r["seed"])
    return {"seeds": [r["seed"] for r in runs], "test_mse": [r["test_mse"] for r in runs]}
