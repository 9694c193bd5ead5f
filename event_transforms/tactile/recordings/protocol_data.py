"""What the protocol reads from a folder of recordings: its scene data (:func:`load_recording_data`,
a :class:`~event_transforms.tactile.copies.SceneData`) and its benchmark scene (:class:`RecordingScene`)."""

from __future__ import annotations

__all__ = ["RecordingScene", "load_recording_data"]

import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from torch import Tensor

from ..benchmark_scenes import BenchmarkScene, Session
from .dataset import RecordingSet
from .layout import SPLITS, RecordingSettings


def load_recording_data(
    root: str | os.PathLike[str],
    settings: RecordingSettings | None = None,
    *,
    cache: str | os.PathLike[str] | None = None,
    name: str | None = None,
    log: Any = None,
    deployment: bool = True,
) -> Any:
    """A folder of recordings as the protocol's :class:`~event_transforms.tactile.copies.SceneData`.

    ``train`` and ``holdout`` come from the training recordings, ``val`` and ``test`` from
    the labelled deployment recordings (see *Splits* in the module docstring). The scene
    (:class:`RecordingScene`) holds :func:`~event_transforms.infer_scene` on the training
    windows and the deployment windows that are not test data (validation and unlabeled
    recordings), as frames, with the sizes of
    ``diameter_mm`` where given; its gaps are the inferred ones and its policy (``inferred``,
    ``independent``, ``hybrid``) the inferred scene's. The timing gap comes from lags measured
    against the force labels of the training and validation recordings (one per whole
    recording) where both exist, else from the frames alone; test recordings are never read. The noise bank (for ``noise``) is the
    deployment windows' quietest frames; the prior's bank (``prior``, ``everything``) the
    training windows' quietest frames (another camera, or the same one, at hand).

    With ``deployment=False`` a folder of training recordings only loads (for training a
    model, never for the benchmark): validation and test are empty and the scene is inferred
    from the training windows alone (no gap).

    Returns:
        A ``SceneData`` whose ``dataset`` attribute describes the data (folder, files,
        content hash, settings, crop, recordings and windows per split).
    """
    from ...inference import sequence_statistics
    from ..lags import infer_scene_with_lags
    from ..copies import SceneData

    start = time.perf_counter()
    settings = settings or RecordingSettings()
    root = Path(root)
    splits = {s: RecordingSet(root, split=s, settings=settings, cache=cache, log=log, deployment=deployment)
              for s in SPLITS}
    settings = splits["train"].settings  # the sensor size resolved
    crop = splits["train"].crop
    for s, data in splits.items():  # every split on the one grid
        if len(data) and tuple(data[0][0].shape) != tuple(splits["train"][0][0].shape):
            raise ValueError(f"split {s!r}: windows of shape {tuple(data[0][0].shape)} differ from the training "
                             f"windows' {tuple(splits['train'][0][0].shape)}; give one crop size")
    train_frames = splits["train"].frames
    if len(train_frames) < 2:
        raise ValueError(
            f"{len(train_frames)} training window(s): the scene inference needs at least 2; a recording of F frames "
            f"gives (F - frames) // stride + 1 windows of frames={settings.frames}: lower frames= or stride=")
    deploy_frames = torch.cat([splits["val"].frames, splits["unlabeled"].frames])
    if not len(deploy_frames):
        if log:
            log("no deployment recordings: the scene is inferred from the training windows alone (no gap)")
        deploy_frames = train_frames
    train_sizes = splits["train"].diameters
    deploy_sizes = _sizes(splits["val"], splits["test"], splits["unlabeled"])
    # lags from the labelled recordings (training, and the deployment's validation recordings;
    # never test data), one per whole recording
    labelled_train, labelled_deploy = splits["train"].labelled, splits["val"].labelled
    labelled = labelled_train is not None and labelled_deploy is not None
    inferred = infer_scene_with_lags(train_frames, deploy_frames, train_sizes=train_sizes,
                                     deploy_sizes=deploy_sizes if deploy_sizes and len(deploy_sizes) == 1 else None,
                                     frame_ms=settings.frame_ms, labelled_train=labelled_train if labelled else None,
                                     labelled_deploy=labelled_deploy if labelled else None)

    def quiet(frames: Tensor) -> Tensor:
        stats = sequence_statistics(frames, frame_ms=settings.frame_ms)
        n, k = stats["quiet"].shape
        return frames.gather(1, stats["quiet"].view(n, k, 1, 1, 1).expand(n, k, *frames.shape[2:])).reshape(
            n * k, *frames.shape[2:])

    table = splits["train"].all_recordings
    dataset = {
        "kind": "recordings",
        "folder": str(root.resolve()),
        "files": len(table) + sum(r.force is not None for r in table) + 1,
        "content_hash": splits["train"].dataset_hash,
        "settings": {**settings.as_dict(), "crop": list(crop)},
        "crop": list(crop),
        "crop_source": splits["train"].crop_source,
        "recordings": {s: len(d.recordings) for s, d in splits.items()},
        "windows": {s: len(d) for s, d in splits.items()},
        "left_out_frames": sum(d.left_out_frames for d in splits.values()),
        # with-labels (the comparator of inferred) is a row where the inference read these labels
        "inferred_reads_labels": labelled,
        "inferred_from": f"{len(train_frames)} training windows of {len(splits['train'].recordings)} recordings and "
                         f"{len(deploy_frames)} deployment windows of " + (
                             f"{len(splits['val'].recordings)} validation and {len(splits['unlabeled'].recordings)} "
                             "unlabeled recordings; frames only" if len(splits["val"]) + len(splits["unlabeled"])
                             else "the training recordings (no deployment recording); frames only") + (
                             f"; lags from {len(labelled_train[0])} training and {len(labelled_deploy[0])} "  # type: ignore[index]
                             "validation recordings against their force labels" if labelled else ""),
    }
    scene = RecordingScene.build(name or root.resolve().name, settings, train_sizes, deploy_sizes, inferred,
                                 quiet(train_frames), dataset)
    return SceneData(scene, splits["train"], splits["val"], splits["test"], quiet(deploy_frames),
                     time.perf_counter() - start, holdout=splits["holdout"] if len(splits["holdout"]) else None,
                     dataset=dataset)


def _sizes(*sets: RecordingSet) -> tuple[float, ...] | None:
    sizes: set[float] = set()
    for data in sets:
        if data.recordings:
            found = data.diameters
            if found is None:
                return None
            sizes |= set(found)
    return tuple(sorted(sizes)) or None


@dataclass(frozen=True)
class RecordingScene(BenchmarkScene):
    """A benchmark scene made of a user's recordings: the gaps are those
    :func:`~event_transforms.infer_scene` finds (size from the ``diameter_mm`` column),
    the policy is the inferred scene's, and nothing is simulated.

    The sessions carry only what the protocol reads from them (sizes, frames per window,
    frame length, sensor size); their simulator settings describe no data.
    """

    inferred: Any = field(default=None, compare=False, hash=False, repr=False)
    prior_bank: Any = field(default=None, compare=False, hash=False, repr=False)
    dataset: Any = field(default=None, compare=False, hash=False, repr=False)

    @classmethod
    def build(cls, name: str, settings: RecordingSettings, train_sizes: Any, deploy_sizes: Any, inferred: Any,
              prior_bank: Tensor, dataset: dict[str, Any]) -> RecordingScene:
        from ..simulation import SimulatorConfig

        assert settings.sensor_size is not None  # resolved by RecordingSet
        config = SimulatorConfig(sensor_size=settings.sensor_size, n_frames=settings.frames,
                                 frame_ms=float(settings.frame_ms), substep_ms=float(settings.frame_ms))
        # without sizes the sessions hold a placeholder size, never read (no size gap)
        train = Session(tuple(train_sizes or (1.0,)), config)
        deploy = Session(tuple(deploy_sizes or train_sizes or (1.0,)), config)
        gaps = ", ".join(inferred.gaps) or "none"
        description = f"own recordings in {dataset['folder']} (inferred gaps: {gaps})"
        return cls(name, description, train, deploy, (), inferred=inferred, prior_bank=prior_bank, dataset=dataset)

    @property
    def gaps(self) -> tuple[str, ...]:
        return tuple(self.inferred.gaps)

    def gap_sizes(self) -> dict[str, dict[str, tuple[Any, Any]]]:
        """factor -> statistic -> (training mean, deployment mean) of the inferred gaps."""
        evidence = self.inferred.evidence or {}
        out: dict[str, dict[str, tuple[Any, Any]]] = {}
        for factor in self.gaps:
            if factor == "size":
                size = evidence.get("size", {})
                out["size"] = {"diameters_mm": (size.get("train_sizes"), size.get("deploy_sizes"))}
            elif factor in evidence and "statistic" in evidence[factor]:
                e = evidence[factor]
                out[factor] = {e["statistic"]: (round(e["train"]["mean"], 3), round(e["deploy"]["mean"], 3))}
        return out

    @property
    def target_size(self) -> float | None:
        return self.inferred.target_size if "size" in self.gaps else None

    def library_scene(self, noise_bank: Tensor | None = None, **kwargs: Any) -> Any:
        """The inferred :class:`~event_transforms.Scene` (its policy uses its own estimates)."""
        return self.inferred
