"""Every limit of a protocol run on its data, checked before any training (issue 44).

A run that would die after binning and training (a window too short for the phase scores, a
batch larger than the training set, a noise bank shorter than a window) or whose numbers would
mean nothing (no hold-out for the stopping rule, no validation or test window) is refused
here, by name, with the option to change spelled as the interface the caller used:
``frames=`` in Python, ``--frames`` on the command line (:func:`check_run_limits`). The limits
are stated in ``docs/recordings.md``.
"""

from __future__ import annotations

__all__ = ["MIN_FRAMES", "MIN_TRAINING_RECORDINGS", "check_run_limits", "holdout_note", "option"]

from collections.abc import Mapping, Sequence
from typing import Any

from ..training import PHASE_EDGE

#: The fewest frames a window of the protocol needs: the test MSE is scored per grasp phase
#: (:func:`~event_transforms.tactile.training.phase_mse`), ``PHASE_EDGE`` frames of grasp and of
#: release and at least one of hold between.
MIN_FRAMES = 2 * PHASE_EDGE + 1

#: The fewest training recordings that leave a hold-out for the stopping rule (the last third,
#: ``n // 3``, is held out).
MIN_TRAINING_RECORDINGS = 3

#: Each option as Python and the command line spell it.
_OPTIONS = {
    "frames": ("frames=", "--frames"),
    "stride": ("stride=", "--stride"),
    "batch_size": ("ProtocolConfig(batch_size=)", "--batch-size"),
    "methods": ("methods=", "--methods"),
}


def option(name: str, cli: bool, value: Any = None) -> str:
    """``name`` as the interface spells it (``frames=8`` or ``--frames 8``)."""
    python, line = _OPTIONS[name]
    if value is None:
        return line if cli else python
    if cli:
        return f"{line} {value}"
    return f"{python[:-2]}={value})" if python.endswith("=)") else f"{python}{value}"


def holdout_note(data: Any) -> str:
    """Why a folder of recordings has no hold-out and what is kept instead (``""`` when it has one)."""
    if data.holdout is not None and len(data.holdout):
        return ""
    counts = (data.dataset or {}).get("recordings", {})
    n = counts.get("train", len(data.train))
    return (f"no hold-out: {n} training recording(s), of which the last third ({n} // 3 = {n // 3}) would be held out "
            f"for the stopping rule; give at least {MIN_TRAINING_RECORDINGS} training recordings, or mark one "
            "split=holdout in recordings.csv. The final weights are kept")


def check_run_limits(data: Mapping[str, Any], methods: Mapping[str, Sequence[str]], config: Any, *,
                     cli: bool = False) -> list[str]:
    """Refuse, before any training, a run whose data cannot carry it; return what it runs without.

    Checked for every scene: windows of at least :data:`MIN_FRAMES` frames; a batch no larger
    than the training windows; a noise bank (``noise`` and the policies that add recorded
    noise) of at least a window's frames. For a folder of recordings also at least one
    validation and one test window; a folder without a hold-out (fewer than
    :data:`MIN_TRAINING_RECORDINGS` training recordings and no ``split`` column) runs with
    the final weights and no convergence judgement, which the returned notes say.

    Args:
        data: scene name -> :class:`~event_transforms.tactile.copies.SceneData`.
        methods: scene name -> the methods the run trains there.
        config: the run's :class:`~event_transforms.tactile.protocol.config.ProtocolConfig`.
        cli: name the options as the command line spells them (``--frames``), else as
            Python does (``frames=``).

    Returns:
        One line per scene that runs without something (no hold-out), for the log.

    Raises:
        ValueError: the first limit a scene's data does not meet, naming the option to change.

    Example:
        >>> import torch
        >>> from types import SimpleNamespace
        >>> windows = [(torch.zeros(8, 2, 4, 4), torch.zeros(8), {})] * 4
        >>> data = SimpleNamespace(train=windows, val=windows, test=windows, holdout=windows, dataset=None,
        ...                        noise_bank=None, scene=None)
        >>> check_run_limits({"mine": data}, {"mine": ["none"]}, SimpleNamespace(batch_size=2), cli=True)
        Traceback (most recent call last):
        ...
        ValueError: scene 'mine': windows of 8 frames (--frames 8), but the protocol scores the grasp, hold and release phases (5 frames of grasp and of release, at least one of hold), so a window needs at least 11 frames: give --frames 11 or more
    """
    notes: list[str] = []
    for name, d in data.items():
        where = f"scene {name!r}"
        if not len(d.train):
            raise ValueError(f"{where}: no training window; lower {option('frames', cli)} or {option('stride', cli)}")
        frames = int(d.train[0][0].shape[0])
        if frames < MIN_FRAMES:
            raise ValueError(
                f"{where}: windows of {frames} frames ({option('frames', cli, frames)}), but the protocol scores the "
                f"grasp, hold and release phases ({PHASE_EDGE} frames of grasp and of release, at least one of "
                f"hold), so a window needs at least {MIN_FRAMES} frames: give {option('frames', cli, MIN_FRAMES)} "
                "or more")
        recordings = (d.dataset or {}).get("kind") == "recordings"
        if recordings:
            counts = d.dataset["recordings"]
            note = holdout_note(d)
            if note:
                notes.append(f"{where}: {note}, and convergence is not judged (the stopping rule and the "
                             "convergence verdicts read the hold-out curve)")
            for split, role in (("val", "validation"), ("test", "test")):
                if not len(getattr(d, split)):
                    raise ValueError(
                        f"{where}: no {role} window ({counts.get(split, 0)} {role} recording(s) of fewer than "
                        f"{frames} frames each); the {role} split is cut from the labelled deployment recordings: "
                        f"give more, or lower {option('frames', cli)}")
        if config.batch_size > len(d.train):
            source = (f"{len(d.train)} training windows ({d.dataset['recordings']['train']} recordings)"
                      if recordings else f"{len(d.train)} training items")
            raise ValueError(
                f"{where}: {option('batch_size', cli, config.batch_size)} is more than its {source}: a step "
                f"would repeat items within its batch; give {option('batch_size', cli, len(d.train))} or fewer")
        _check_banks(where, d, methods.get(name, ()), frames, cli)
    return notes


def _check_banks(where: str, data: Any, methods: Sequence[str], frames: int, cli: bool) -> None:
    """Every noise bank a method's transform draws windows from holds at least a window's frames
    (the transform is built as the run builds it, and each module's ``bank`` read)."""
    import torch

    from ..methods import parse_method

    if data.scene is None:
        return
    for method in methods:
        try:
            parsed = parse_method(method, scene=data.scene)
            transform = parsed.build(data.noise_bank if parsed.needs_noise_bank else None)
        except ValueError:
            continue  # choose_methods and the run name what a scene cannot build
        if not isinstance(transform, torch.nn.Module):
            continue
        for module in transform.modules():
            bank = getattr(module, "bank", None)
            if isinstance(bank, torch.Tensor) and bank.dim() == 4 and int(bank.shape[0]) < frames:
                source = ("the training recordings' quiet frames" if method.strip().lower().startswith(
                    ("prior", "everything")) else "the deployment recordings' quiet frames")
                raise ValueError(
                    f"{where}: method {method!r} adds recorded noise from a bank of {int(bank.shape[0])} frames "
                    f"({source}, 4 per window), fewer than a window's {frames} frames: give "
                    f"{option('frames', cli, int(bank.shape[0]))} or fewer, more recordings, or leave {method!r} out "
                    f"of {option('methods', cli)}")
