"""Fresh data per seed: each seed of a protocol run on the simulated scenes draws its own data set."""

from __future__ import annotations

import json

import pytest
import torch

from event_transforms.tactile.copies import data_seed_offset, load_scene_data
from event_transforms.tactile.protocol import ProtocolConfig, run_protocol, run_unit
from event_transforms.tactile.protocol.shared import content_key, training_key
from event_transforms.tactile.report import table_coverage

TINY = ProtocolConfig(steps=3, batch_size=4, eval_every=2, hidden_channels=(2,), input_pool=14)
SEEDS = [0, 1]


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    return str(tmp_path_factory.mktemp("cache"))


@pytest.fixture(scope="module")
def fresh(root, tmp_path_factory):
    torch.set_num_threads(1)
    out = tmp_path_factory.mktemp("fresh")
    results = run_protocol(["control"], SEEDS, out, config=TINY, methods=["none", "fs2"], root=root,
                           budget_check=False, measure_time=False)
    return out, results


@pytest.mark.slow
def test_the_default_is_fresh_data_and_seeds_draw_disjoint_grasps(root):
    assert ProtocolConfig().resample == "fresh"
    first, again, other = (load_scene_data("control", root, data_seed=s) for s in (0, 0, 1))
    base = load_scene_data("control", root)
    seeds = {name: {d_.meta(i)["seed"] for d_ in (getattr(d, s) for s in ("train", "holdout", "val", "test"))
                    for i in range(len(d_))} for name, d in (("first", first), ("other", other), ("base", base))}
    assert not seeds["first"] & seeds["other"] and not seeds["first"] & seeds["base"]  # new grasps, none shared
    assert min(seeds["first"]) == data_seed_offset(0) and min(seeds["other"]) == data_seed_offset(1)
    # the same seed twice reads the same grasps; another seed other grasps, train and test alike
    assert content_key(first.test) == content_key(again.test) and training_key(first) == training_key(again)
    assert content_key(first.test) != content_key(other.test) and training_key(first) != training_key(other)
    assert torch.equal(first.noise_bank, again.noise_bank) and not torch.equal(first.noise_bank, other.noise_bank)
    # with-labels adds what inferred reads, the base data set's validation grasps, whatever the seed
    assert content_key(first.labelled) == content_key(other.labelled) == content_key(base.val)


@pytest.mark.slow
def test_results_record_each_seeds_data(fresh, root):
    out, results = fresh
    saved = json.loads((out / "results.json").read_text())
    assert saved["config"]["resample"] == "fresh" and saved["data_per_seed"] == "fresh"
    identity = saved["scenes"]["control"]["data_per_seed"]
    assert identity["rule"] == "fresh" and sorted(identity["seeds"]) == ["0", "1"]
    for seed in SEEDS:
        d = load_scene_data("control", root, data_seed=seed)
        entry = identity["seeds"][str(seed)]
        assert entry["sequence_seed_offset"] == data_seed_offset(seed)
        assert entry["training_hash"] == training_key(d) and entry["evaluation_hash"] == content_key(d.val, d.test)
    assert identity["seeds"]["0"]["evaluation_hash"] != identity["seeds"]["1"]["evaluation_hash"]
    # the baselines are fitted and scored on each seed's own data set
    ridge = saved["scenes"]["control"]["baselines"]["cumulative-count-ridge"]
    assert ridge["resample"] == "fresh" and len(ridge["test_mse_per_seed"]) == 2
    assert ridge["test_mse_per_seed"][0] != ridge["test_mse_per_seed"][1]
    report = (out / "results.md").read_text()
    assert table_coverage("fresh") in report and "new data sets from the simulator" in report


@pytest.mark.slow
def test_within_a_seed_the_methods_are_paired_on_that_seeds_data(fresh, root):
    _, results = fresh
    methods = results["scenes"]["control"]["methods"]
    for seed in SEEDS:  # the run's members of a seed are those trained on the seed's own data, from its seed
        alone = run_unit("control", ["none", "fs2"], [seed], TINY, load_scene_data("control", root, data_seed=seed),
                         progress=False)
        for method in ("none", "fs2"):
            index = methods[method]["seeds"].index(seed)
            assert methods[method]["test_mse"][index] == alone[method][0]["test_mse"]
    assert methods["none"]["test_mse"][0] != methods["none"]["test_mse"][1]  # two data sets, two scores


def test_given_data_keep_the_resampling_and_every_table_says_so(tmp_path):
    from tests.tactile.test_cli import fake_data

    small = ProtocolConfig(steps=3, batch_size=4, eval_every=2, hidden_channels=(2,), input_pool=4)
    results = run_protocol(["control"], [0, 1], tmp_path, config=small, methods=["none", "fs2"],
                           data={"control": fake_data("control")}, budget_check=False, measure_time=False)
    assert results["config"]["resample"] == "bootstrap" and results["data_per_seed"] == "bootstrap"
    assert results["scenes"]["control"]["data_per_seed"]["rule"] == "bootstrap"
    report = (tmp_path / "results.md").read_text()
    assert report.count(table_coverage("bootstrap")) == 2 and "3.7×" in table_coverage("bootstrap")
