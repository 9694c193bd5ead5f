"""The model benchmarks' table writers on tiny runs (3 steps, tiny data): the scripts cannot rot."""

from __future__ import annotations

from pathlib import Path

import torch

from benchmarks import default_model
from event_transforms.tactile.copies import SceneData
from event_transforms.tactile.report import run_verdicts
from event_transforms.tactile.scenes import get_scene


def _items(n: int, g: torch.Generator, t: int = 12, size: int = 28) -> list:
    frames = torch.poisson(torch.full((n, t, 2, size, size), 0.5), generator=g)
    force = (frames[:, :, 0] - frames[:, :, 1]).sum((-2, -1)).cumsum(1) / 50 + torch.rand(n, t, generator=g)
    return [(f, y, {"diameter_mm": 15.0}) for f, y in zip(frames, force)]


def tiny_data(scenes: list[str], seed: int = 0) -> dict[str, SceneData]:
    g = torch.Generator().manual_seed(seed)
    bank = torch.poisson(torch.full((20, 2, 28, 28), 0.05), generator=g)
    return {s: SceneData(get_scene(s), _items(6, g), _items(4, g), _items(6, g), bank, holdout=_items(3, g))
            for s in scenes}


def test_default_model_comparison_page(tmp_path: Path) -> None:
    scenes = ["paper", "timing"]
    data = tiny_data(scenes)
    methods = default_model.comparison_methods(scenes)
    assert methods == {"paper": ("none", "resize", "stretch"), "timing": ("none", "fs2")}
    runs = {model: default_model.run_model(default_model.model_config(model, steps=3, eval_every=1, batch_size=2),
                                           methods, [0, 1, 2], tmp_path / model, data=data)
            for model in default_model.MODELS}
    page = default_model.format_comparison(runs, [0, 1, 2], note="a note")
    assert runs["default"]["results"]["config"]["hidden_channels"] == (8, 16)
    assert runs["quick"]["results"]["config"]["input_pool"] == 14
    shared = run_verdicts(runs["quick"]["text"]).keys() & run_verdicts(runs["default"]["text"]).keys()
    assert ("timing", "fs2", "vs none") in shared
    assert f"Of the {len(shared)} verdicts both runs print" in page
    assert "## Summary table, quick model" in page and "## Summary table, default model" in page
    assert "a note" in page and "| default | (8, 16) | 4 |" in page
