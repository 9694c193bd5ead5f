"""The model benchmarks' table writers on tiny runs (3 steps, tiny data): the scripts cannot rot."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from benchmarks.tactile import default_model, model_sweep
from event_transforms.tactile.copies import SceneData
from event_transforms.tactile.report import run_verdicts
from event_transforms.tactile.benchmark_scenes import get_scene


def _items(n: int, g: torch.Generator, t: int = 12, size: int = 28) -> list:
    frames = torch.poisson(torch.full((n, t, 2, size, size), 0.5), generator=g)
    force = (frames[:, :, 0] - frames[:, :, 1]).sum((-2, -1)).cumsum(1) / 50 + torch.rand(n, t, generator=g)
    return [(f, y, {"diameter_mm": 15.0}) for f, y in zip(frames, force)]


def tiny_data(scenes: list[str], seed: int = 0) -> dict[str, SceneData]:
    g = torch.Generator().manual_seed(seed)
    bank = torch.poisson(torch.full((20, 2, 28, 28), 0.05), generator=g)
    return {s: SceneData(get_scene(s), _items(6, g), _items(4, g), _items(6, g), bank, holdout=_items(3, g))
            for s in scenes}


@pytest.mark.slow  # two protocol runs of 3 steps: ~3 s alone, ~7 s on a loaded machine
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


def test_model_sweep_table(tmp_path: Path) -> None:
    data = tiny_data(["control", "paper"])
    data["timing"] = SceneData(get_scene("timing"), data["control"].train, data["control"].val, data["control"].test,
                               data["control"].noise_bank, holdout=data["control"].holdout)
    assert model_sweep.distinct_training_sets(data) == {"control": ["control", "timing"], "paper": ["paper"]}
    configs = [((2,), 14, 3), ((2,), 7, 3)]
    state_path = tmp_path / "state.json"
    state = model_sweep.run_sweep(data, configs, [0, 1], state_path, eval_every=1, batch_size=2)
    assert list(state["configs"]) == ["(2,) / pool 14 / 3 steps", "(2,) / pool 7 / 3 steps"]
    row = state["configs"]["(2,) / pool 14 / 3 steps"]
    assert len(row["control"]["holdout_mse"]) == 2 and row["control"]["s_per_member_step"] > 0
    assert set(state["baselines"]) == {"control", "paper"}
    # a rerun reads finished configurations back instead of training them again
    again = model_sweep.run_sweep(data, configs, [0, 1], state_path, eval_every=1, batch_size=2)
    assert again["configs"] == state["configs"]
    plan = model_sweep.parse_plan("x members (method × seed), 1,000 member-steps; 600 member-steps are trained in "
                                  "the main phase; total at most 5,000")
    assert plan == {"total": 5000, "main": 1000, "main_trained": 600, "trained": 4600}
    timing = model_sweep.time_configs(data["control"], configs, [0, 1], steps=2, repeats=2, batch_size=2)
    assert list(timing) == list(state["configs"]) and all(value > 0 for value in timing.values())
    page = model_sweep.format_sweep({**state, "timing": timing}, {3: plan}, header=["# head"])
    lines = page.splitlines()
    assert lines[0] == "# head" and "| control test | control hold-out | paper hold-out |" in lines[1]
    assert len([line for line in lines if line.startswith("| (2,)")]) == 2
    assert sum("(baseline)" in line for line in lines) == 2
    assert "both baselines on the control's test set and on every training-session hold-out" in page


def test_model_sweep_winners_are_below_both_baselines() -> None:
    def scores(value: float) -> dict:
        return {"holdout_mse": [value, value], "test_mse": [value, value], "s_per_member_step": 0.01}

    state = {"control": "control", "training_sets": {"control": ["control"], "paper": ["paper"]},
             "baselines": {s: {name: {"holdout_mse": [1.0], "test_mse": [1.0]} for name in model_sweep.BASELINES}
                           for s in ("control", "paper")},
             "configs": {"good": {"steps": 3, "hidden_channels": [2], "input_pool": 4, "control": scores(0.5), "paper": scores(0.9)},
                         "bad": {"steps": 3, "hidden_channels": [2], "input_pool": 4, "control": scores(0.5), "paper": scores(1.1)}}}
    plan = {"total": 6000, "main": 1000, "main_trained": 400, "trained": 5400}
    page = model_sweep.format_sweep(state, {3: plan})
    assert "| good | **0.500** | **0.500** | **0.900** | 3/3 | 0.0100 | 0.0100 | 1.0× | 0.5 / 0.5 |" in page
    assert "| bad | **0.500** | **0.500** | 1.100 | 2/3 |" in page
    assert "hold-out: good (main job ≈ 0.5 min, est.)." in page
    scaled = model_sweep.format_sweep(state, {3: plan}, recorded_min=10.0)
    assert "| 3/3 | 0.0100 | 0.0100 | 1.0× | 0.5 / 0.5 | 10.0 |" in scaled
    assert "hold-out: good (main job ≈ 10.0 min, scaled from the recorded main job)." in scaled
