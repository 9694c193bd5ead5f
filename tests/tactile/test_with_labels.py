"""The comparator with labels: the labelled deployment recordings ``inferred`` reads, added to training."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from event_transforms.tactile.copies import SceneData, WithLabels
from event_transforms.tactile.methods import methods_for, parse_method, reads_labels
from event_transforms.tactile.protocol import ProtocolConfig, run_unit
from event_transforms.tactile.protocol.shared import plan_sharing
from event_transforms.tactile.benchmark_scenes import get_scene
from event_transforms.tactile.training import train
from tests.tactile.test_cli import fake_data

TINY = ProtocolConfig(steps=4, batch_size=4, eval_every=2, hidden_channels=(2,), input_pool=4, resample="none")


def test_the_row_sits_beside_inferred_wherever_inferred_reads_labels():
    method = parse_method("with-labels", scene="timing")
    assert method.copies == 0 and method.reads_deployment_labels and method.build() is None
    for scene in ("paper", "paper-offset", "paper-membrane", "timing", "orientation"):
        names = methods_for(scene)
        assert names[names.index("inferred") + 1] == "with-labels"
    assert "with-labels" not in methods_for("control")  # no gap: no inferred, no comparator
    with pytest.raises(ValueError, match="scene 'control' has none"):
        parse_method("with-labels", scene="control")
    with pytest.raises(ValueError, match="takes no x<copies>"):
        parse_method("with-labelsx2", scene="timing")

    @dataclasses.dataclass
    class Folder:  # a folder of recordings: a row only where the inference read labelled recordings
        dataset: dict

    assert reads_labels(get_scene("timing")) and not reads_labels(Folder({"kind": "recordings"}))
    assert reads_labels(Folder({"inferred_reads_labels": True}))


def test_it_trains_on_the_validation_items_too_and_stops_on_the_training_hold_out():
    data = fake_data("timing")
    trained = train(data, ["none", "with-labels"], [0], progress=False, **TINY.training_settings())
    assert trained.train_items == [len(data.train), len(data.train) + len(data.val)]
    both = WithLabels(data.train, data.val)
    assert torch.equal(both[len(data.train)][0], data.val[0][0]) and both.meta(0) == data.train[0][2]
    unit = run_unit("timing", ["none", "with-labels"], [0, 1], TINY, data, progress=False)
    for record in unit["with-labels"]:  # the same budget and stopping rule as every row
        assert record["steps"] == TINY.steps and record["stopping"] == "best hold-out MSE"
        assert record["trained_on_val"] and record["train_items"] == len(data.train) + len(data.val)
    assert not any(r["trained_on_val"] for r in unit["none"])
    assert [r["test_mse"] for r in unit["with-labels"]] != [r["test_mse"] for r in unit["none"]]


def test_scenes_share_it_only_when_their_deployment_labels_agree():
    a = fake_data("timing")
    same = SceneData(get_scene("paper-offset"), a.train, a.val, a.test, a.noise_bank, holdout=a.holdout)
    other = SceneData(get_scene("orientation"), a.train, fake_data("paper").test, a.test, a.noise_bank,
                      holdout=a.holdout)
    chosen = {"timing": ("none", "with-labels"), "paper-offset": ("none", "with-labels"),
              "orientation": ("none", "with-labels")}
    sharing = plan_sharing(chosen, {"timing": a, "paper-offset": same, "orientation": other})
    assert sharing.owner[("paper-offset", "with-labels")] == ("timing", "with-labels")
    assert sharing.owner[("orientation", "with-labels")] == ("orientation", "with-labels")  # other labels
    assert sharing.owner[("orientation", "none")] == ("timing", "none")


def test_the_findings_say_whether_inferring_beats_the_labels():
    from event_transforms.tactile.report import format_findings

    rows = {"inferred": {"test_mse": [2.0, 2.2], "delta_vs_none": None},
            "with-labels": {"test_mse": [1.0, 1.2], "delta_vs_none": None}}
    lines = format_findings("timing", {"baselines": {}, "methods": rows})
    assert any("2.10 vs 1.10 N² test MSE, so inferring does not beat using the labels" in line for line in lines)
    assert any("stopped on the training session's hold-out" in line for line in lines)


def test_at_equal_cost_it_steps_like_none_without_a_ratio_in_the_cost_table(monkeypatch, tmp_path):
    from event_transforms.tactile.protocol import phases, run_protocol
    from event_transforms.tactile.protocol.costs import COST_TABLE_FORMAT, cost_key

    config = ProtocolConfig(**{**TINY.__dict__, "resample": "bootstrap"})
    timing = {"single_model_wall_s": {"median": 10.0, "min": 9.0, "max": 11.0, "repeats": 3},
              "single_model_scene": "timing",
              "online_aug_s_per_epoch": {"timing": {"none": None, "fs2": 0.0, "with-labels": None}}}
    monkeypatch.setattr(phases, "measure_timing", lambda *a, **k: timing)
    costs = {"format": COST_TABLE_FORMAT, "config": cost_key(config), "ratios": {"timing": {"none": 1.0, "fs2": 2.0}}}
    results = run_protocol(["timing"], [0, 1], tmp_path, config=config,
                                        methods=["none", "fs2", "with-labels"], data={"timing": fake_data("timing")},
                                        budget_check=False, equal_time=True, cost_table=costs)
    row = results["scenes"]["timing"]["methods"]["with-labels"]
    assert row["cost_ratio"] == 1.0 and row["equal_time"]["steps"] == TINY.steps
    assert results["scenes"]["timing"]["methods"]["fs2"]["equal_time"]["steps"] == TINY.steps // 2


def test_every_scene_has_the_network_without_global_inputs_in_an_ensemble_of_its_own():
    from event_transforms.tactile.protocol.plan import work_units

    method = parse_method("none-local", scene="control")
    assert method.copies == 0 and method.build() is None and dict(method.model) == {"global_inputs": False}
    for scene in ("control", "paper", "timing", "orientation"):
        assert methods_for(scene)[-1] == "none-local"
    data = fake_data("timing")
    trained = train(data, ["none-local"], [0], progress=False, **TINY.training_settings())
    assert trained.model.global_inputs is False
    with pytest.raises(ValueError, match="separate ensembles"):
        train(data, ["none", "none-local"], [0], progress=False, **TINY.training_settings())
    units = work_units(["timing"], {"timing": ("none", "fs2", "none-local")}, "scene")
    assert sorted(u.methods for u in units) == [("none", "fs2"), ("none-local",)]
    unit = run_unit("timing", ["none-local"], [0], TINY, data, progress=False)
    alone = run_unit("timing", ["none"], [0], TINY, data, progress=False)
    assert unit["none-local"][0]["test_mse"] != alone["none"][0]["test_mse"]
    sharing = plan_sharing({"timing": ("none", "none-local")}, {"timing": data})
    assert sharing.owner[("timing", "none-local")] == ("timing", "none-local")  # not the none member


def test_the_findings_say_which_model_the_verdicts_use():
    from event_transforms.tactile.report import format_findings

    rows = {"none": {"test_mse": [1.0, 1.2], "delta_vs_none": None},
            "none-local": {"test_mse": [3.0, 3.2], "delta_vs_none": None}}
    lines = format_findings("control", {"baselines": {"physics least-squares": {"test_mse": 0.5}}, "methods": rows})
    line = next(line for line in lines if "none-local" in line)
    assert "3.10 N² against 1.10 for none" in line and "physics least-squares 0.50" in line
    assert "The verdicts use the model with global inputs" in line


def test_the_best_row_against_the_physics_model_is_never_the_one_that_read_deployment_labels():
    from event_transforms.tactile.report import format_physics_comparison

    line = format_physics_comparison({"baselines": {"physics least-squares": {"test_mse": 1.0}},
                                      "methods": {"none": {"test_mse": [2.0]}, "with-labels": {"test_mse": [0.5]}}})
    assert line.startswith("best row: none 2.00")


def test_it_adds_the_recordings_inferred_reads_where_the_data_name_them():
    data = fake_data("timing")
    named = dataclasses.replace(data, labelled=fake_data("paper").test)
    trained = train(named, ["with-labels"], [0], progress=False, **TINY.training_settings())
    assert trained.train_items == [len(data.train) + len(named.labelled)]
