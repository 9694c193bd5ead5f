"""Cost from a table, not a stopwatch: equal-cost step counts follow from a cost
table measured once, interleaved, so they do not move with the machine's load."""

from __future__ import annotations

import json

import pytest

from event_transforms.tactile.protocol import run_protocol
from event_transforms.tactile.protocol.costs import (
    COST_TABLE_FORMAT,
    QUICK_COST_TABLE,
    cost_key,
    equal_cost_steps,
    load_cost_table,
    measure_costs,
    ratio_of,
)

from tests.tactile.test_cli import TINY, fake_data


def test_equal_cost_steps_is_a_floor_with_no_grain():
    assert [equal_cost_steps(300, r) for r in (1.0, 1.2, 1.25, 1.5, 2.0, 7.9, 1e9)] == [300, 250, 240, 200, 150, 37, 1]
    for bad in (0.99, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="ratio must be a finite number >= 1"):
            equal_cost_steps(300, bad)


def test_measured_ratios_are_one_for_none_and_above_for_online_work():
    data = {"timing": fake_data("timing")}
    table = measure_costs(["timing"], {"timing": ("none", "fs2", "tes2:0.5")}, data, TINY, repeats=2, probe_steps=2)
    ratios = table["ratios"]["timing"]
    assert ratios["none"] == 1.0 and ratios["fs2"] > 1.0 and ratios["tes2:0.5"] > 1.0
    assert table["format"] == COST_TABLE_FORMAT and table["config"] == cost_key(TINY) and table["repeats"] == 2
    assert load_cost_table(table)["ratios"] == table["ratios"]


def test_a_run_takes_its_equal_cost_steps_from_the_table_not_the_clock(tmp_path):
    data = {"timing": fake_data("timing")}
    table = {"format": COST_TABLE_FORMAT, "config": cost_key(TINY),
             "ratios": {"timing": {"none": 1.0, "fs2": 1.5, "fs-1": 3.0}}}
    results = run_protocol(["timing"], [0, 1], tmp_path / "a", config=TINY, methods=["none", "fs2", "fs-1"], data=data,
                           budget_check=False, equal_time=True, cost_table=table)
    methods = results["scenes"]["timing"]["methods"]
    assert methods["fs2"]["cost_ratio"] == 1.5 and methods["fs2"]["equal_time"]["steps"] == 2  # floor(3 / 1.5)
    assert methods["fs-1"]["equal_time"]["steps"] == 1
    assert results["cost_table"]["source"] == "given"
    with pytest.raises(ValueError, match=r"cost table \(given\) was measured for"):
        run_protocol(["timing"], [0], tmp_path / "b", config=TINY, methods=["none", "fs2"], data=data,
                     budget_check=False, equal_time=True, cost_table={**table, "config": {**table["config"], "batch_size": 99}})
    with pytest.raises(ValueError, match=r"no ratio for 'fs-1' on scene 'timing'"):
        ratio_of({"ratios": {"timing": {"fs2": 1.2}}}, "timing", "fs-1")


def test_a_run_without_a_table_measures_and_keeps_one(tmp_path):
    data = {"timing": fake_data("timing")}
    run_protocol(["timing"], [0], tmp_path, config=TINY, methods=["none", "fs2"], data=data, budget_check=False,
                 equal_time=True)
    kept = json.loads((tmp_path / "cost_table.json").read_text())
    assert kept["ratios"]["timing"]["fs2"] >= 1.0 and "measured" in kept["source"]


def test_the_committed_table_covers_the_quick_run():
    """The README's quick run reads the committed table: it names its machine and commit and
    holds a ratio for every scene and method the quick run trains; `--plan` states the time from it."""
    from event_transforms.tactile.commands import quick_config
    from event_transforms.tactile.commands import QUICK
    from event_transforms.tactile.protocol.plan import choose_methods

    table = load_cost_table(QUICK_COST_TABLE)
    assert table["config"] == cost_key(quick_config())
    assert table["environment"]["cpu_model"] and len(str(table["commit"])) >= 7
    assert 0 < table["ensemble_s_per_member_step"] < table["train_s_per_step"]
    scenes = list(QUICK["scenes"])
    for scene, methods in choose_methods(scenes).items():
        for method in methods:
            assert ratio_of(table, scene, method) >= 1.0
        assert ratio_of(table, scene, "none") == 1.0


def test_equal_cost_units_carry_their_own_steps():
    """The equal-cost phase runs as one phase over every job: each unit at its own step count,
    named and keyed by it, so units of two step counts never overwrite each other."""
    from event_transforms.tactile.protocol.plan import Unit

    a, b = Unit("paper", ("stretch",), (), 229), Unit("paper", ("stretch",), (), 207)
    assert a.slug == "paper_stretch@229" and b.slug == "paper_stretch@207"
    assert Unit("paper", ("stretch",)).slug == "paper_stretch"
