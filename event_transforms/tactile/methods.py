"""Method names of the benchmark: what each name builds, and which methods a scene runs.

=================  ===============================================================
``none``           no synthetic copies
``rot<deg>``       ``RandomRotation(±deg)`` about the event centroid, e.g. ``rot45``
``resize``         ``ResizeToTarget(scene target)``: β = target / the sample's size
``resize-hertz``   the same with β = (target / size)^½ (Hertz contact width ∝ √D)
``noise``          ``AddNoise`` with static-scene frames of the deployment camera
``fs<j>``          ``FrameShift(j)``, e.g. ``fs-1`` (one frame earlier), ``fs2``
``tes<j>:<ζ>``     ``TemporalEventShift(j, ζ)``, e.g. ``tes-2:0.5``
``matched``        every gap's matched augmentation, one per copy (``OneOf``): the oracle of
                   a scene with two gaps or more (``paper-offset``: FS-1 or the physics
                   stretch to 15 mm), the policy ``inferred`` should find; simulated scenes only
``independent``    the scene's policy, one effect per copy (``OneOf``); on ``paper`` and
                   ``optical-paper``, the paper's resize or FS-1
``hybrid``         the same effects stacked on every copy (``Compose``)
``none-local``     no synthetic copies, and the reference model without ``global_inputs`` (its
                   head reads the ConvLSTM's features only, not the inputs' spatial means: the
                   network on its own); every scene has it beside ``none``, whose model (with
                   global inputs) every other row and every verdict uses
``with-labels``    no synthetic copies: the labelled deployment recordings ``inferred`` reads
                   (the deployment's validation grasps and their forces) added to training,
                   the same step budget; the comparator a user with labels would try first;
                   wherever ``inferred`` reads labels (every gapped simulated scene, a folder
                   whose inference measured lags from labelled recordings)
``<name>x<k>``     ``k`` synthetic copies per item, e.g. ``tes-2:0.5x10``
=================  ===============================================================
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import torch
from torch import nn

from ..scenes import ResizeToTarget, Scene
from ..transforms import AddNoise, FrameShift, RandomRotation, TemporalEventShift
from .policies import POLICY_METHODS, build_policy, stretch_policy
from .benchmark_scenes import SCENES, BenchmarkScene, get_scene

__all__ = [
    "PAPER_METHODS",
    "QUICK_METHODS",
    "EXTRA_METHODS",
    "PAPER_SCENE",
    "Method",
    "parse_method",
    "methods_for",
]

#: The methods the paper compares, in its order.
PAPER_METHODS: tuple[str, ...] = (
    "none", "rot45", "resize", "noise", "fs-1", "tes-2:0.5", "independent", "hybrid",
    "tes-2:0.5x10",
)

#: The paper's scene policy: sizes 12 and 18 mm to 15 mm, and FS-1 (the paper's best shift).
PAPER_SCENE = Scene(training_sizes=(12.0, 18.0), target_size=15.0, lag_shifts=(-1,), size_transform="resize")


@dataclass(frozen=True)
class Method:
    """A named augmentation: the transform every training item's synthetic copies get.

    The transform is called with each item's metadata, so one transform serves every
    bolt size (:class:`~event_transforms.ResizeToTarget` reads the size from it).

    Args:
        name: label in tables and file names.
        make: builds the transform from the noise bank (``None`` if there is none), or
            ``None`` for no synthetic copies.
        copies: synthetic copies per training item (0 = none).
        needs_noise_bank: the transform needs a static-scene noise bank.
        model: settings of the member's ``ForceRegressor`` that differ from the run's (``none-local``:
            ``(("global_inputs", False),)``); members of one ensemble share them.
        reads_deployment_labels: the method trains on the deployment's labelled validation
            items too (``with-labels``); they then score nothing of its training (the stopping
            rule reads the training session's hold-out, as for every method).
    """

    name: str
    make: Callable[[torch.Tensor | None], nn.Module] | None
    copies: int = 1
    needs_noise_bank: bool = False
    reads_deployment_labels: bool = False
    model: tuple[tuple[str, Any], ...] = ()

    @classmethod
    def from_transform(cls, name: str, transform: nn.Module, copies: int = 1) -> Method:
        """A method applying ``transform`` to every item."""
        if not isinstance(transform, nn.Module):
            raise TypeError(f"transform must be an nn.Module, got {type(transform).__name__}")
        return cls(name, lambda bank: transform, copies)

    @classmethod
    def from_scene(cls, name: str, scene: Scene, copies: int = 1, *, combination: str = "independent") -> Method:
        """A method from a :class:`~event_transforms.scenes.Scene`'s policy.

        Example:
            >>> scene = Scene(training_sizes=(12.0, 18.0), target_size=15.0, lag_shifts=(-1,))
            >>> [type(t).__name__ for t in Method.from_scene("scene", scene).build().transforms]
            ['RandomFrameShift', 'StretchToTarget']
        """
        if not isinstance(scene, Scene):
            raise TypeError(f"scene must be a Scene, got {type(scene).__name__}")
        return cls(name, lambda bank: scene.policy(combination), copies)

    def build(self, noise_bank: torch.Tensor | None = None) -> nn.Module | None:
        """The transform of the synthetic copies, or ``None`` for none."""
        if self.make is None or self.copies == 0:
            return None
        if self.needs_noise_bank and noise_bank is None:
            raise ValueError(f"method {self.name!r} needs a static-scene noise bank, got None")
        return self.make(noise_bank)


_NUMBER = r"[+-]?\d+(?:\.\d*)?(?:[eE][+-]?\d+)?"
_PATTERN = re.compile(
    rf"^(?P<base>none-local|none|with-labels|resize-hertz|resize|noise|independent|hybrid|matched|stretch|inferred|prior|everything"
    rf"|rot(?P<deg>{_NUMBER})"
    rf"|fs(?P<fs>[+-]?\d+)|tes(?P<tes>[+-]?\d+):(?P<frac>{_NUMBER}))(?:x(?P<copies>\d+))?$"
)


def _add_noise(bank: torch.Tensor | None) -> nn.Module:
    """The ``noise`` method's transform (:meth:`Method.build` refuses a missing bank first)."""
    if bank is None:
        raise ValueError("method 'noise' needs a static-scene noise bank, got None")
    return AddNoise(bank)


def parse_method(name: str, *, copies: int = 1, scene: str | BenchmarkScene = "paper") -> Method:
    """Turn a method name (see the module docstring) into a :class:`Method` for ``scene``.

    Args:
        name: e.g. ``"none"``, ``"rot45"``, ``"resize"``, ``"fs-1"``, ``"tes-2:0.5x10"``.
        copies: synthetic copies per item when the name has no ``x<k>`` suffix.
        scene: the benchmark scene (its target size, gaps and policy).

    Example:
        >>> m = parse_method("tes-2:0.5x10")
        >>> m.copies, m.build()
        (10, TemporalEventShift(shift=-2, fraction=0.5, mode='exact'))
        >>> parse_method("resize").build()
        ResizeToTarget(target_size=15.0, key='diameter_mm', exponent=1.0, center='mass', mode='bilinear')
        >>> parse_method("resize-hertz", scene="size-extrapolation").build().target_size
        18.0
        >>> parse_method("none").copies
        0
    """
    if not isinstance(name, str):
        raise TypeError(f"method name must be a str, got {type(name).__name__}")
    scene = get_scene(scene)
    match = _PATTERN.match(name.strip().lower())
    if match is None:
        raise ValueError(
            f"unknown method {name!r}; expected none, rot<deg>, resize, resize-hertz, stretch, noise, fs<j>, "
            "tes<j>:<fraction>, independent, hybrid, matched, inferred, prior, everything, with-labels or none-local, "
            "optionally "
            "followed by x<copies>"
        )
    base = match["base"]
    if match["copies"] is not None:
        copies = int(match["copies"])
    if isinstance(copies, bool) or not isinstance(copies, int) or copies < 0:
        raise ValueError(f"copies must be a non-negative int, got {copies!r}")
    if base == "none":
        return Method(name, None, 0)
    if base == "none-local":
        if match["copies"] is not None:
            raise ValueError(f"method {name!r}: none-local makes no synthetic copies, so it takes no x<copies>")
        return Method(name, None, 0, model=(("global_inputs", False),))
    if base == "with-labels":
        if match["copies"] is not None:
            raise ValueError(f"method {name!r}: with-labels makes no synthetic copies, so it takes no x<copies>")
        if not scene.gaps:
            raise ValueError(f"method {name!r} is the comparator of inferred, which a scene without gaps lacks; "
                             f"scene {scene.name!r} has none")
        if not reads_labels(scene):
            raise ValueError(f"method {name!r} needs labelled deployment recordings that inferred reads; scene "
                             f"{scene.name!r}'s inference read none")
        return Method(name, None, 0, reads_deployment_labels=True)
    if base in POLICY_METHODS:  # scene-level policies (tactile/policies.py)
        if not scene.gaps:
            raise ValueError(f"method {name!r} simulates a scene's gaps; scene {scene.name!r} has none")
        if base == "stretch":
            stretch_policy(scene)  # refuses a scene without a size gap now, by name
        return Method(name, lambda bank: build_policy(base, scene), copies)
    if base in ("resize", "resize-hertz"):
        target = scene.target_size
        if target is None:
            raise ValueError(
                f"method {name!r} needs a scene whose deployment size differs from training; "
                f"scene {scene.name!r} has none"
            )
        exponent = 0.5 if base == "resize-hertz" else 1.0
        return Method(name, lambda bank: ResizeToTarget(target, exponent=exponent), copies)
    if base == "noise":
        return Method(name, _add_noise, copies, needs_noise_bank=True)
    if base == "matched":
        return _matched(name, scene, copies)
    if base in ("independent", "hybrid"):
        if scene.name in ("paper", "optical-paper"):  # the paper's combination, on both generators
            return Method.from_scene(name, PAPER_SCENE, copies, combination=base)
        needs_bank = "noise" in scene.gaps
        return Method(
            name, lambda bank: scene.library_scene(bank).policy(base), copies, needs_noise_bank=needs_bank
        )
    frames = scene.train.config.n_frames
    make: Callable[[torch.Tensor | None], nn.Module]
    if match["deg"] is not None:
        degrees = float(match["deg"])
        make = lambda bank: RandomRotation(degrees)  # noqa: E731
    elif match["fs"] is not None:
        shift = int(match["fs"])
        make = lambda bank: FrameShift(shift)  # noqa: E731
    else:
        shift, fraction = int(match["tes"]), float(match["frac"])
        if not 0 <= fraction <= 1:
            raise ValueError(f"TES fraction must lie in [0, 1], got {fraction!r} in {name!r}")
        make = lambda bank: TemporalEventShift(shift, fraction)  # noqa: E731
    if match["deg"] is None and abs(shift) >= frames:
        raise ValueError(
            f"method {name!r} shifts by {shift} frames, but scene {scene.name!r} has {frames} frames per "
            f"sequence: every event would leave the sequence; use |shift| < {frames}"
        )
    try:
        make(None)  # refuse bad settings (e.g. a negative angle) here, not inside a worker
    except (ValueError, TypeError) as error:
        raise ValueError(f"method {name!r}: {error}") from None
    return Method(name, make, copies)


def _matched_policy(scene: BenchmarkScene, bank: torch.Tensor | None) -> nn.Module:
    """The scene's declared gaps, each closed by its matched augmentation with the physics' size
    transform (``stretch``), one per copy."""
    return scene.library_scene(bank, size_transform="stretch").policy("independent")


def _matched(name: str, scene: BenchmarkScene, copies: int) -> Method:
    """``matched`` (:func:`_matched_policy`); refused on recordings and where no gap is declared."""
    if getattr(scene, "inferred", None) is not None:
        raise ValueError(f"method {name!r} needs a simulated scene whose gaps are known; scene {scene.name!r} is "
                         "made of recordings, whose gaps are only inferred: use 'inferred'")
    if not scene.gaps:
        raise ValueError(f"method {name!r} simulates a scene's gaps; scene {scene.name!r} has none")
    needs_bank = "noise" in scene.gaps
    if not _matched_effects(scene):
        raise ValueError(f"method {name!r}: scene {scene.name!r}'s gaps ({', '.join(scene.gaps)}) have no matched "
                         "augmentation")
    return Method(name, lambda bank: _matched_policy(scene, bank), copies, needs_noise_bank=needs_bank)


def _matched_effects(scene: BenchmarkScene) -> int:
    """How many matched augmentations ``matched`` combines on ``scene`` (a placeholder bank
    stands in for the noise bank: only the policy's structure is read)."""
    bank = torch.zeros(1, 2, 1, 1) if "noise" in scene.gaps else None
    return len(getattr(_matched_policy(scene, bank), "transforms", ()))


def _combines(scene: BenchmarkScene) -> bool:
    """Whether ``matched`` combines two matched augmentations or more on ``scene``."""
    return getattr(scene, "inferred", None) is None and bool(scene.gaps) and _matched_effects(scene) >= 2


#: Quick mode's methods of the scenes without a paper list: none and the matched ones;
#: the control runs the other scenes' matched methods that need no size gap.
QUICK_METHODS: dict[str, tuple[str, ...]] = {
    "paper": PAPER_METHODS,
    "control": ("none", "rot50", "fs2", "noise"),
}
#: The optical scenes run their built-in role's quick methods.
QUICK_METHODS.update({"optical-paper": QUICK_METHODS["paper"], "optical-control": QUICK_METHODS["control"]})

#: Rows every scene runs after its own methods, in quick and full mode, where the scene can
#: build them (``parse_method`` accepts them): adding a policy row is one name here.
#: ``with-labels`` sits beside ``inferred``: the comparator of the policy that reads those labels.
#: ``none-local`` (the network without global inputs) closes every scene's list.
EXTRA_METHODS: tuple[str, ...] = ("stretch", "inferred", "with-labels", "prior", "everything", "none-local")


def reads_labels(scene: BenchmarkScene) -> bool:
    """Whether ``inferred`` reads labelled deployment recordings on ``scene``: always on the
    simulated scenes (the validation grasps' forces, for the lags); on a folder of recordings,
    where its inference measured lags from labelled recordings (``dataset["inferred_reads_labels"]``)."""
    dataset = getattr(scene, "dataset", None)
    if isinstance(dataset, dict):
        return bool(dataset.get("inferred_reads_labels", False))
    return True


def methods_for(scene: str | BenchmarkScene, *, full: bool = False) -> tuple[str, ...]:
    """The methods a scene runs: quick — ``none`` + its matched methods (the paper's list on
    ``paper``, other scenes' matched methods on ``control``); full — the paper's list (where
    defined) and every scene's matched methods that the scene can build (``independent`` and
    ``hybrid`` only where they combine two effects or more: on ``paper``); both with
    ``matched`` where it combines two matched augmentations or more, and followed by the
    :data:`EXTRA_METHODS` the scene can build.

    Example:
        >>> methods_for("timing")
        ('none', 'fs2', 'tes2:0.5', 'inferred', 'with-labels', 'prior', 'everything', 'none-local')
        >>> methods_for("paper-offset")[-5:]
        ('inferred', 'with-labels', 'prior', 'everything', 'none-local')
    """
    scene = get_scene(scene)
    if not full:
        names = list(QUICK_METHODS.get(scene.name, ("none", *scene.matched_methods)))
        names += ["matched"] if _combines(scene) else []
        return tuple(dict.fromkeys(names + [m for m in EXTRA_METHODS if _buildable(m, scene)]))
    names = list(PAPER_METHODS) + [m for s in SCENES.values() for m in s.matched_methods] + ["matched"]
    names += list(EXTRA_METHODS)
    usable = []
    for name in dict.fromkeys(names):
        if name in ("independent", "hybrid") and scene.name != "paper" and len(scene.gaps) < 2:
            continue  # with one effect or none, the combinations are the matched method or a copy
        if name == "matched" and not _combines(scene):
            continue
        if _buildable(name, scene):
            usable.append(name)
    return tuple(usable)


def _buildable(name: str, scene: BenchmarkScene) -> bool:
    try:
        parse_method(name, scene=scene)
    except ValueError:
        return False
    return True

