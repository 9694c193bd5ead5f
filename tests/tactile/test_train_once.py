"""Train once: a member whose training reads exactly what another scene's
member reads is trained once and scored for both, with the same numbers as training it again."""

from __future__ import annotations

import json

import pytest
import torch

from event_transforms.tactile.copies import SceneData
from event_transforms.tactile.protocol import run_protocol
from event_transforms.tactile.protocol.shared import member_key, plan_sharing, training_key
from event_transforms.tactile.benchmark_scenes import get_scene

from tests.tactile.test_cli import TINY, FakeGrasps, fake_data


def _other_deployment(scene: str) -> SceneData:
    """``scene`` with the training data of :func:`fake_data` and its own validation and test sets."""
    base = fake_data(scene)
    return SceneData(get_scene(scene), base.train, FakeGrasps(7, diameters=(15.0,), seed=12),
                     FakeGrasps(8, diameters=(15.0,), seed=13), base.noise_bank, holdout=base.holdout)


def test_members_are_keyed_by_what_their_training_reads():
    control, timing = fake_data("control"), _other_deployment("timing")
    assert training_key(control) == training_key(timing)  # val/test differ, training does not
    assert member_key(control, "none") == member_key(timing, "none")
    assert member_key(control, "fs2") == member_key(timing, "fs2")
    assert member_key(control, "fs2") != member_key(control, "fs-1")  # another policy
    assert member_key(control, "fs2x2") != member_key(control, "fs2")  # another number of copies
    other_train = SceneData(get_scene("control"), FakeGrasps(6, seed=21), control.val, control.test,
                            control.noise_bank, holdout=control.holdout)
    assert member_key(other_train, "none") != member_key(control, "none")
    other_bank = SceneData(get_scene("control"), control.train, control.val, control.test,
                           torch.zeros_like(control.noise_bank), holdout=control.holdout)
    assert member_key(other_bank, "none") == member_key(control, "none")  # none never reads the bank
    assert member_key(other_bank, "noise") != member_key(control, "noise")  # noise does


def test_the_first_scene_owns_a_shared_member():
    data = {"control": fake_data("control"), "timing": _other_deployment("timing")}
    sharing = plan_sharing({"control": ("none", "fs2"), "timing": ("none", "fs2", "fs-1")}, data)
    assert sharing.owned == {"control": ("none", "fs2"), "timing": ("fs-1",)}
    assert sharing.owner[("timing", "fs2")] == ("control", "fs2") and sharing.shared == 2
    assert sharing.also("control", ("none", "fs2")) == (("none", "timing", "none"), ("fs2", "timing", "fs2"))


@pytest.mark.slow
def test_a_borrowed_member_scores_what_training_it_again_scores(tmp_path):
    seeds, methods = [0, 1], ["none", "fs2"]
    data = {"control": fake_data("control"), "timing": _other_deployment("timing")}
    shared = run_protocol(["control", "timing"], seeds, tmp_path / "shared", config=TINY, methods=methods,
                          data=data, budget_check=False, measure_time=False)
    alone = run_protocol(["timing"], seeds, tmp_path / "alone", config=TINY, methods=methods,
                         data={"timing": data["timing"]}, budget_check=False, measure_time=False)
    assert shared["plan"]["shared_members"] == len(methods) * len(seeds)  # timing trains nothing of its own
    assert shared["plan"]["trained_members"] == len(methods) * len(seeds)
    for method in methods:
        for key in ("test_mse", "val_mse", "holdout_mse", "best_step"):
            assert shared["scenes"]["timing"]["methods"][method][key] == alone["scenes"]["timing"]["methods"][method][key]
    # the borrowed scores are the timing scene's own (other test sequences), not control's
    assert shared["scenes"]["timing"]["methods"]["none"]["test_mse"] != shared["scenes"]["control"]["methods"]["none"]["test_mse"]
    runs = list((tmp_path / "shared" / "runs").glob("*/*.json"))
    stored = [json.loads(p.read_text()) for p in runs if p.name != "config.json"]
    assert all(s["key"]["scene"] == "control" for s in stored)  # no unit trained for timing
    assert any("timing::none" in s["result"] for s in stored)


def test_the_datasets_docstring_names_the_scenes_that_share_training_data():
    """The docstring's groups are the built-in scenes' training sessions (the issue found it wrong)."""
    from event_transforms.tactile import datasets
    from event_transforms.tactile.benchmark_scenes import SCENES

    groups: dict[str, list[str]] = {}
    for name in SCENES:
        groups.setdefault(repr(get_scene(name).train), []).append(name)
    shared = sorted(sorted(g) for g in groups.values() if len(g) > 1)
    assert shared == [["control", "noise", "orientation", "timing"], ["paper", "paper-membrane"]]
    doc = " ".join(datasets.TactileGrasps.__doc__.split())
    assert "``control``, ``timing``, ``orientation`` and ``noise`` train on one data set" in doc
    assert "``paper`` and ``paper-membrane`` on another" in doc
