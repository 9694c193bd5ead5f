"""Tests for the protocol runner and the ``event-transforms`` command line (in-process)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
import torch

import event_transforms as et
from event_transforms.tactile import cli, figures, protocol
from event_transforms.tactile.copies import DeviceAugment, MaterializedDataset, OnlineCopies, SceneData, build_training_set, paired_batches
from event_transforms.tactile.methods import PAPER_METHODS, QUICK_METHODS, Method, methods_for, parse_method
from event_transforms.tactile.protocol import ProtocolConfig, run_protocol, run_unit
from event_transforms.tactile.protocol import config as protocol_config
from event_transforms.tactile.protocol import phases as protocol_phases
from event_transforms.tactile.protocol import plan as protocol_plan
from event_transforms.tactile.protocol import timing
from event_transforms.tactile.report import format_scene_table
from event_transforms.tactile.runs import folder_name
from event_transforms.tactile.benchmark_scenes import SCENES, get_scene
from event_transforms.tactile.stats import holm, paired_t, student_t_quantile
from event_transforms.tactile.stopwatch import Stopwatch
from tests.tactile.test_training import FakeGrasps


pytestmark = pytest.mark.usefixtures("one_thread")  # see conftest.py


TINY = ProtocolConfig(steps=3, batch_size=4, eval_every=2, hidden_channels=(2,), input_pool=4)


def fake_data(scene: str = "paper") -> SceneData:
    g = torch.Generator().manual_seed(9)
    bank = torch.poisson(torch.full((40, 2, 16, 12), 0.2), generator=g)
    return SceneData(
        get_scene(scene), FakeGrasps(6, seed=1), FakeGrasps(7, diameters=(15.0,), seed=2),
        FakeGrasps(8, diameters=(15.0,), seed=3), bank, holdout=FakeGrasps(4, seed=4),
    )


@pytest.fixture(scope="module")
def data():
    return fake_data()


class TestParseMethod:
    def test_paper_methods(self):
        built = {name: parse_method(name) for name in PAPER_METHODS}
        assert built["none"].copies == 0 and built["none"].build() is None
        assert isinstance(built["rot45"].build(), et.RandomRotation)
        resize = built["resize"].build()
        assert isinstance(resize, et.ResizeToTarget) and resize.target_size == 15.0
        scales = resize.make_params((2, 4, 2, 8, 8), metadata={"diameter_mm": [12.0, 18.0]})["scale"]
        assert scales.tolist() == pytest.approx([1.25, 15 / 18])
        bank = torch.zeros(40, 2, 5, 5)
        assert isinstance(built["noise"].build(bank), et.AddNoise)
        assert built["noise"].needs_noise_bank
        with pytest.raises(ValueError, match="noise bank"):
            built["noise"].build(None)
        assert isinstance(built["fs-1"].build(), et.FrameShift)
        assert isinstance(built["tes-2:0.5"].build(), et.TemporalEventShift)
        # independent and hybrid come from one scene, so they hold the same steps
        independent, hybrid = built["independent"].build(), built["hybrid"].build()
        assert isinstance(independent, et.OneOf) and isinstance(hybrid, et.Compose)
        for policy in (independent, hybrid):
            kinds = [type(t) for t in policy.transforms]
            assert kinds == [et.RandomFrameShift, et.ResizeToTarget]
            assert policy.transforms[0].shifts == (-1,)
        assert built["tes-2:0.5x10"].copies == 10
        assert all(built[n].copies == 1 for n in PAPER_METHODS if n not in ("none", "tes-2:0.5x10"))

    def test_variants(self):
        assert parse_method("fs2").build()(torch.ones(3, 2, 1, 1))[:, 0, 0, 0].tolist() == [0, 0, 1]
        assert parse_method("rot10x3").copies == 3
        assert parse_method("resize", copies=4).copies == 4
        assert parse_method(" FS-1 ").copies == 1

    @pytest.mark.parametrize(
        "name", ["", "rot", "fs", "tes-2", "tes-2:", "fs-1x", "blur", "tes-1:1.5", "fs100", "fs-36", "tes36:0.5",
                 "rot-45"],
    )
    def test_bad_names(self, name):
        with pytest.raises(ValueError, match="method|fraction"):
            parse_method(name)
        with pytest.raises(TypeError):
            parse_method(3)

    def test_custom_methods(self):
        flip = Method.from_transform("shift", et.FrameShift(1), copies=2)
        assert flip.copies == 2 and isinstance(flip.build(), et.FrameShift)
        from event_transforms.scenes import Scene

        scene = Scene(training_sizes=(12.0, 18.0), target_size=15.0, orientation_deg=10)
        method = Method.from_scene("mine", scene, copies=2, combination="hybrid")
        assert method.copies == 2
        assert [type(t) for t in method.build().transforms] == [et.StretchToTarget, et.RandomRotation]
        with pytest.raises(TypeError):
            Method.from_transform("x", lambda f: f)
        with pytest.raises(TypeError):
            Method.from_scene("x", "scene")

    def test_scene_policy_resizes_per_item(self, data):
        """AugmentedDataset hands each item's metadata through the timing wrapper."""
        from event_transforms.scenes import Scene

        scene = Scene(training_sizes=(12.0, 18.0), target_size=15.0)
        method = Method.from_scene("size", scene)
        train = build_training_set(method, data, seed=0, fixed=True, stopwatch=Stopwatch())
        n = len(data.train)
        assert {data.train[i][2]["diameter_mm"] for i in range(n)} == {12.0, 18.0}
        for index in range(n):
            frames, _, meta = train[n + index]
            original, _, original_meta = train[index]
            assert meta == original_meta
            torch.testing.assert_close(frames, et.Stretch((15.0 / meta["diameter_mm"]) ** 0.5)(original))


class TestTrainingSet:
    def test_sizes_and_labels(self, data):
        watch = Stopwatch()
        for name, size in [("none", 6), ("resize", 12), ("fs-1x3", 24)]:
            train = build_training_set(parse_method(name), data, seed=0, fixed=True, stopwatch=watch)
            assert len(train) == size
        labels = sorted(float(train[i][1].sum()) for i in range(len(train)))
        originals = sorted(float(data.train[i][1].sum()) for i in range(6))
        assert labels == sorted(originals * 4)

    def test_resize_per_diameter(self, data):
        train = build_training_set(parse_method("resize"), data, seed=0, fixed=True, stopwatch=Stopwatch())
        n = len(data.train)
        for index in range(n):  # copy n + i is item i resized by 15 mm / its own diameter
            frames, _, meta = data.train[index]
            expected = et.Resize(15.0 / meta["diameter_mm"])(frames)
            torch.testing.assert_close(train[n + index][0], expected)

    def test_fixed_copies_repeat_and_online_differ(self, data):
        method = parse_method("rot45")
        fixed = build_training_set(method, data, seed=0, fixed=True, stopwatch=Stopwatch())
        assert torch.equal(fixed[8][0], fixed[8][0])
        online = build_training_set(method, data, seed=0, fixed=False, stopwatch=Stopwatch())
        assert not torch.equal(online[8][0], online[8][0])
        torch.testing.assert_close(online[0][0], fixed[0][0])  # originals untouched

    def test_stopwatch_counts_only_copies(self, data):
        watch = Stopwatch()
        train = build_training_set(parse_method("fs-1"), data, seed=0, fixed=True, stopwatch=watch)
        for i in range(len(train)):
            train[i]
        assert watch.calls == 2 * 6  # each copy: one draw and one application, timed once


class TestMaterializedDataset:
    def test_round_trip(self, data):
        train = build_training_set(parse_method("resize"), data, seed=0, fixed=True, stopwatch=Stopwatch())
        kept = MaterializedDataset(train)
        assert len(kept) == len(train) == 12
        for i in range(12):
            a, b = kept[i], train[i]
            assert a[0].dtype == torch.float32 and torch.equal(a[0], b[0])
            assert torch.equal(a[1], b[1]) and a[2] == b[2]
        assert kept.items[0][0].dtype == torch.int16  # integer counts stored compactly
        assert kept.items[6][0].dtype == torch.float32  # interpolated counts kept exactly

    def test_counts_transform_once(self, data):
        watch = Stopwatch()
        train = build_training_set(parse_method("fs-1"), data, seed=0, fixed=True, stopwatch=watch)
        kept = MaterializedDataset(train)
        for _ in range(3):
            for i in range(len(kept)):
                kept[i]
        assert watch.calls == 2 * 6  # each copy: one draw and one application, timed once


class TestScenesAndMethods:
    def test_scene_methods(self):
        policies = ("inferred", "with-labels", "prior", "everything", "none-local")
        assert methods_for("paper") == PAPER_METHODS + ("stretch", *policies)
        assert methods_for("timing") == ("none", "fs2", "tes2:0.5", *policies)
        assert methods_for("control") == QUICK_METHODS["control"] + ("none-local",)
        # two gaps: the matched row (every gap's matched augmentation) beside the single ones
        assert methods_for("paper-offset") == ("none", "fs-1", "tes-2:0.5", "matched", "stretch", *policies)
        assert methods_for("paper-membrane") == ("none", "fs1", "tes1:0.5", "matched", "stretch", *policies)
        assert "matched" in methods_for("paper-lag", full=True) and "matched" not in methods_for("paper", full=True)
        assert methods_for("control")[0] == "none"
        full = methods_for("control", full=True)
        assert "resize" not in full and "rot45" in full and "noise" in full  # no size gap: no resize
        assert {"resize", "resize-hertz", "fs2"} <= set(methods_for("paper", full=True))
        for scene in SCENES:
            for name in methods_for(scene) + methods_for(scene, full=True):
                parse_method(name, scene=scene)

    def test_scene_targets(self):
        assert parse_method("resize", scene="size-extrapolation").build().target_size == 18.0
        assert parse_method("resize-hertz").build().exponent == 0.5
        with pytest.raises(ValueError, match="size"):
            parse_method("resize", scene="timing")
        timing = parse_method("independent", scene="timing").build()
        assert isinstance(timing, et.OneOf) and timing.transforms[0].shifts == (2,)
        noise = parse_method("independent", scene="noise")
        assert noise.needs_noise_bank and isinstance(noise.build(torch.zeros(5, 2, 4, 4)).transforms[0], et.AddNoise)


def _check_shape(saved: dict, scenes: list[str], methods: list[str], seeds: list[int]) -> None:
    """The results.json contract of the protocol issue."""
    assert set(saved) >= {"config", "wall_s", "scenes", "commit", "plan"} and isinstance(saved["wall_s"], float)
    assert saved["commit"] == "unknown" or len(saved["commit"].removesuffix("-dirty")) == 40
    assert list(saved["scenes"]) == scenes
    for name, scene in saved["scenes"].items():
        assert scene["gaps"] == list(get_scene(name).gaps)
        assert scene["matched_methods"] == list(get_scene(name).matched_methods)
        assert set(scene["split_sizes"]) == {"train", "holdout", "val", "test"}
        assert set(scene["baselines"]) == {"global-mean", "per-frame-mean", "cumulative-count-ridge", "physics least-squares"}
        assert all(isinstance(b["test_mse"], float) for b in scene["baselines"].values())
        assert list(scene["methods"]) == methods
        for method, m in scene["methods"].items():
            assert m["seeds"] == seeds
            for key in ("test_mse", "val_mse", "best_step", "holdout_mse"):
                assert len(m[key]) == len(seeds)
            assert all(isinstance(b, int) and 1 <= b <= m["steps"] for b in m["best_step"])
            assert isinstance(m["steps"], int)
            for key in ("aug_s_once", "aug_s_per_epoch", "train_s"):
                assert isinstance(m[key], float) and m[key] >= 0
            if method == "none":
                assert m["delta_vs_none"] is None
            else:
                delta = m["delta_vs_none"]
                assert set(delta) >= {"mean", "ci95", "p_value", "p_holm", "t_p_holm", "significant", "ci95_welch",
                                      "correlation"}
                assert len(delta["ci95"]) == 2
        if (scene["gaps"] and "none" in methods and any(m in methods for m in get_scene(name).matched_methods)
                and saved["config"].get("budget_check", True)):
            check = scene["budget_check"]
            assert set(check) >= {"method", "steps", "steps_2n", "delta", "delta_2n", "ci_family_halfwidth", "robust"}
            assert check["steps_2n"] == 2 * check["steps"] and check["method"] in methods
            # the pre-declared headline: the scene's first matched method the run trains, never the largest |Δ|
            assert check["method"] == next(m for m in get_scene(name).matched_methods if m in methods)
            family = scene["methods"][check["method"]]["delta_vs_none"]["ci_family"]
            assert check["ci_family_halfwidth"] == pytest.approx((family[1] - family[0]) / 2)
            from event_transforms.tactile.stats import significant

            if significant(scene["methods"][check["method"]]["delta_vs_none"]):
                assert check["robust"] == ((check["delta"] > 0) == (check["delta_2n"] > 0)
                                           and abs(check["delta"] - check["delta_2n"]) < check["ci_family_halfwidth"])
            else:  # nothing resolved to re-check
                assert check["robust"] is None
        else:
            assert "budget_check" not in scene


def _group_rank(rank: int, world: int, port: int, scene_data: dict, out: str) -> None:
    import torch.distributed as dist

    torch.set_num_threads(1)
    dist.init_process_group("gloo", init_method=f"tcp://127.0.0.1:{port}", rank=rank, world_size=world)
    try:
        run = TestRunProtocol
        results = run_protocol(run.scenes, run.seeds, out, config=TINY, methods=run.methods, data=scene_data,
                               group="method")
        assert (results == {}) == (rank != 0)
    finally:
        dist.destroy_process_group()


@pytest.fixture(scope="module")
def scene_data():
    return {scene: fake_data(scene) for scene in TestRunProtocol.scenes}


@pytest.fixture(scope="module")
def clean(scene_data, tmp_path_factory):
    out = tmp_path_factory.mktemp("clean")
    run = TestRunProtocol
    return out, run_protocol(run.scenes, run.seeds, out, config=TINY, methods=run.methods, data=scene_data,
                             group="method")


class TestRunProtocol:
    scenes = ["control", "timing"]
    methods = ["none", "fs2", "fs-1"]
    seeds = [0, 1, 2]

    def test_results_file(self, clean):
        out, results = clean
        saved = json.loads((out / "results.json").read_text())
        _check_shape(saved, self.scenes, self.methods, self.seeds)
        assert saved["scenes"]["control"]["gaps"] == [] and saved["scenes"]["timing"]["gaps"] == ["timing"]
        for scene in saved["scenes"].values():
            methods = scene["methods"]
            assert all(m["steps"] == TINY.steps for m in methods.values())  # equal budgets
            assert methods["fs2"]["train_items"] == 12 and methods["none"]["train_items"] == 6
            assert methods["fs2"]["aug_s_once"] > 0 and methods["none"]["aug_s_once"] == 0
            # Δ is paired seed by seed on test MSE, Wilcoxon p Holm-corrected within the scene
            tests = {m: paired_t(methods["none"]["test_mse"], methods[m]["test_mse"]) for m in ("fs2", "fs-1")}
            for m, test in tests.items():
                delta = methods[m]["delta_vs_none"]
                assert delta["mean"] == pytest.approx(test.mean)
                # the moderated interval: the row's variance shrunk toward the family's prior
                prior, var, df = delta["variance_prior"], test.sd ** 2, test.n - 1
                if prior is not None:
                    var, df = (prior["df"] * prior["s2"] + df * var) / (prior["df"] + df), prior["df"] + df
                half = student_t_quantile(0.975, df) * (var / test.n) ** 0.5
                assert delta["ci95"] == pytest.approx([test.mean - half, test.mean + half])
            adjusted = holm([t.wilcoxon_p_value for t in tests.values()])
            assert [methods[m]["delta_vs_none"]["p_holm"] for m in tests] == pytest.approx(adjusted)
            # the paper's 6 + 6 split: its own pairs, Holm-corrected within the scene too
            small = {m: paired_t(methods["none"]["test_mse_paper_split"], methods[m]["test_mse_paper_split"])
                     for m in ("fs2", "fs-1")}
            split = [methods[m]["delta_vs_none_paper_split"] for m in small]
            assert [d["mean"] for d in split] == pytest.approx([t.mean for t in small.values()])
            assert [d["t_p_holm"] for d in split] == pytest.approx(holm([d["t_p_value"] for d in split]))
        report = (out / "results.md").read_text()
        assert "### control" in report and "*cumulative-count-ridge* (baseline)" in report
        assert "6 + 6 split" in report and f"commit `{saved['commit']}`" in report
        assert "budget check of the headline: " in report and "unpaired 95 % CI (unadjusted)" in report
        assert "best row: " in report and "(not converged)" not in report
        # the rules the verdicts were judged by: recorded with their version, and named by the report
        from event_transforms.tactile.protocol.rules import RULES

        assert saved["rules"] == RULES.to_dict() and f"Decision rules version {RULES.version} " in report
        # every cell of the summary table recomputed from the per-seed values alone (what a page publishes)
        from event_transforms.tactile.protocol.recompute import recompute, seed_values
        from event_transforms.tactile.report import format_summary_table

        values = json.loads(json.dumps(seed_values(saved)))
        assert format_summary_table(recompute(values)) == format_summary_table(saved)
        assert format_summary_table(saved) in report

    def test_summary_table_repeats_the_scene_tables(self, clean):
        from tests.tactile.test_results_table import markdown_tables, summary_table

        out, _ = clean
        report = (out / "results.md").read_text()
        summary = summary_table(report)
        scene_tables = [t for t in markdown_tables(report) if t[0][0] == "method" and "aug s once" in t[0]]
        rows = [dict(zip(t[0], row)) for t in scene_tables for row in t[1:]]
        assert len(summary) - 1 == len(rows) and len(scene_tables) == len(self.scenes)
        for line, row in zip(summary[1:], rows):
            cells = dict(zip(summary[0], line))
            assert all(cells[k] == row[k] for k in row if k in cells), (cells, row)
        checked = [dict(zip(summary[0], line)) for line in summary[1:] if line[-1] != "—"]
        assert [c["scene"] for c in checked] == ["timing"] and "at 6 steps" in checked[0]["budget check (headline)"]

    def test_budget_check_is_the_headline_at_twice_the_steps(self, clean):
        """The budget check re-checks the scene's pre-declared headline (its first matched method,
        fs2 for timing), not the largest |Δ| (which regresses toward the mean)."""
        out, results = clean
        check = results["scenes"]["timing"]["budget_check"]
        deltas = results["scenes"]["timing"]["methods"]
        largest = "fs2"
        assert get_scene("timing").matched_methods[0] == largest
        assert check["method"] == largest and check["delta"] == deltas[largest]["delta_vs_none"]["mean"]
        # given data cannot draw fresh data per seed: the run reads each seed's bootstrap resample
        assert results["config"]["resample"] == "bootstrap"
        double = ProtocolConfig(**{**TINY.__dict__, "steps": 2 * TINY.steps, "resample": "bootstrap"})
        folder = out / "runs" / folder_name(double, self.seeds)
        runs = {m: json.loads((folder / f"timing_{m}.json").read_text())["result"][m] for m in ("none", largest)}
        assert all(r["steps"] == 2 * TINY.steps for rs in runs.values() for r in rs)
        expected = paired_t([r["test_mse"] for r in runs["none"]], [r["test_mse"] for r in runs[largest]])
        assert check["delta_2n"] == pytest.approx(expected.mean)
        assert "budget_check" not in results["scenes"]["control"]  # no gap, no check

    def test_stopping_rule_keeps_the_best_hold_out_weights(self, scene_data):
        config = ProtocolConfig(**{**TINY.__dict__, "steps": 6, "eval_every": 2})
        out = protocol.run_unit("control", ["none"], [0, 1], config, scene_data["control"])
        for record in out["none"]:
            history = record["holdout_history"]
            assert history["steps"] == [2, 4, 6] and record["holdout_mse"] == min(history["mse"])
            assert record["best_step"] == history["steps"][history["mse"].index(min(history["mse"]))]

    def test_progress_lines_count_units_and_give_an_overall_eta(self, scene_data, tmp_path, capsys):
        lines = []
        run_protocol(["control"], [0], tmp_path, config=TINY, methods=["none", "fs2"], data=scene_data,
                     group="method", log=lines.append)
        err = capsys.readouterr().err
        assert "unit 1/2 control" in err and "unit 2/2 control" in err and "overall ETA" in err
        assert "hold-out MSE" in err and any(line.startswith("progress lines:") for line in lines)
        assert any(line.startswith("plan: 2 units") for line in lines)

    def test_paired_batches_share_the_originals(self):
        none = paired_batches(6, 0, 4, 30, seed=3)
        for copies in (1, 2, 10):
            batches = paired_batches(6, copies, 4, 30, seed=3)
            assert torch.equal(batches % 6, none)  # the same original at every step and slot
            variants = torch.bincount((batches // 6).flatten(), minlength=copies + 1)
            assert int(variants.max() - variants.min()) <= 6  # each variant read about equally often
        assert not torch.equal(paired_batches(6, 1, 4, 30, seed=4) % 6, none)

    def test_paired_seeds_share_initial_weights(self, scene_data):
        """Seed s gives every method the same start: with no step taken, equal predictions."""
        config = ProtocolConfig(**{**TINY.__dict__, "steps": 1, "lr": 1e-12})
        out = protocol.run_unit("control", ["none", "fs2"], [0, 1], config, scene_data["control"])
        for a, b in zip(out["none"], out["fs2"]):
            assert a["test_mse"] == pytest.approx(b["test_mse"], rel=1e-6)
        assert out["none"][0]["test_mse"] != pytest.approx(out["none"][1]["test_mse"], rel=1e-6)

    def test_resume_after_interruption_gives_same_results(self, clean, scene_data, tmp_path, monkeypatch):
        _, expected = clean
        real, calls = protocol.run_unit, []

        def killed_after_two(*args, **kwargs):
            calls.append(args[:2])
            if len(calls) == 3:
                raise KeyboardInterrupt
            return real(*args, **kwargs)

        monkeypatch.setattr(protocol_phases, "run_unit", killed_after_two)
        with pytest.raises(KeyboardInterrupt):
            run_protocol(self.scenes, self.seeds, tmp_path, config=TINY, methods=self.methods, data=scene_data,
                         group="method")
        monkeypatch.setattr(protocol_phases, "run_unit", real)
        resumed = run_protocol(self.scenes, self.seeds, tmp_path, config=TINY, methods=self.methods,
                               data=scene_data, group="method")
        for scene in self.scenes:
            for method in self.methods:
                assert resumed["scenes"][scene]["methods"][method]["test_mse"] == \
                    expected["scenes"][scene]["methods"][method]["test_mse"]

    def test_one_ensemble_per_scene_matches_one_per_method(self, clean, scene_data, tmp_path):
        _, expected = clean
        grouped = run_protocol(["control"], self.seeds, tmp_path, config=TINY, methods=self.methods,
                               data={"control": scene_data["control"]}, group="scene")
        for method in self.methods:
            assert grouped["scenes"]["control"]["methods"][method]["test_mse"] == pytest.approx(
                expected["scenes"]["control"]["methods"][method]["test_mse"], rel=1e-4)

    @pytest.mark.slow
    def test_two_gloo_ranks_match_one_process(self, clean, scene_data, tmp_path):
        """--jobs 2: two processes joined by torch.distributed (gloo) share the units."""
        _, expected = clean
        results = run_protocol(self.scenes, self.seeds, tmp_path, config=TINY, methods=self.methods,
                               data=scene_data, group="method", jobs=2)
        for scene in self.scenes:
            for method in self.methods:
                assert results["scenes"][scene]["methods"][method]["test_mse"] == \
                    expected["scenes"][scene]["methods"][method]["test_mse"]

    def test_torchrun_style_group_gathers_and_broadcasts_the_budget_check(self, clean, scene_data, tmp_path):
        """Ranks of an initialised group (as under torchrun): rank 0 gathers every unit and picks
        the budget check's method for all ranks; the numbers are those of one process."""
        import torch.multiprocessing as mp

        from event_transforms.tactile.distributed import _free_port

        _, expected = clean
        mp.spawn(_group_rank, args=(2, _free_port(), scene_data, str(tmp_path)), nprocs=2, join=True)
        results = json.loads((tmp_path / "results.json").read_text())
        assert results["scenes"]["timing"]["budget_check"] == expected["scenes"]["timing"]["budget_check"]
        for scene in self.scenes:
            for method in self.methods:
                assert results["scenes"][scene]["methods"][method]["test_mse"] == \
                    expected["scenes"][scene]["methods"][method]["test_mse"]

    def test_online_copies_are_made_per_batch_on_the_device_and_reproducible(self, scene_data):
        online = ProtocolConfig(**{**TINY.__dict__, "fixed": False})
        first = protocol.run_unit("control", ["none", "rot45"], [0, 1], online, scene_data["control"])
        again = protocol.run_unit("control", ["none", "rot45"], [0, 1], online, scene_data["control"])
        for a, b in zip(first["rot45"], again["rot45"]):
            assert a["test_mse"] == b["test_mse"]
            assert a["aug_s_once"] == 0 and a["aug_s_per_epoch"] > 0 and a["train_items"] == 12
        assert all(r["aug_s_per_epoch"] == 0 for r in first["none"])

    def test_device_augment_transforms_only_copies(self):
        frames = torch.poisson(torch.full((4, 14, 2, 16, 12), 0.5))
        metas = [{"copy": c, "diameter_mm": 12.0} for c in (0, 1, 0, 2)]
        out = DeviceAugment(et.FrameShift(1), seed=0)(frames, metas)
        assert torch.equal(out[[0, 2]], frames[[0, 2]])
        assert torch.equal(out[[1, 3]], et.FrameShift(1)(frames[[1, 3]]))
        copies = OnlineCopies(FakeGrasps(3, seed=1), 2)
        assert len(copies) == 9 and copies[7][2]["copy"] == 2 and torch.equal(copies[7][0], copies[1][0])

    def test_bad_arguments(self, scene_data, tmp_path):
        with pytest.raises(ValueError, match="distinct"):
            run_protocol(["control"], [0], tmp_path, config=TINY, methods=["none", "none"], data=scene_data)
        with pytest.raises(ValueError, match="scene"):
            run_protocol(["nowhere"], [0], tmp_path, config=TINY, data=scene_data)
        with pytest.raises(ValueError, match="size"):
            run_protocol(["control"], [0], tmp_path, config=TINY, methods=["resize"], data=scene_data)
        with pytest.raises(ValueError, match="jobs"):
            run_protocol(["control"], [0], tmp_path, config=TINY, methods=["none"], data=scene_data, jobs=0)

    def test_one_seed_table_has_no_spread(self, clean):
        _, results = clean
        one = {**results["scenes"]["control"]}
        one["methods"] = {m: {**v, "test_mse": v["test_mse"][:1], "best_step": v["best_step"][:1]}
                          for m, v in one["methods"].items()}
        assert "±" not in format_scene_table("control", one)
        assert "±" in format_scene_table("control", results["scenes"]["control"])


class TestCommandLine:
    def test_reproduce_smoke(self, tmp_path, monkeypatch, capsys):
        monkeypatch.setattr(protocol_plan, "load_scene_data", lambda scene, root=None, **k: fake_data(scene))
        out = tmp_path / "res"
        code = cli.main([
            "reproduce", "--scenes", "control", "--methods", "none", "fs-1", "--seeds", "0,1", "--steps", "2",
            "--hidden-channels", "2", "--input-pool", "4", "--batch-size", "4", "--jobs", "1", "--out", str(out),
        ])
        assert code == 0
        printed = capsys.readouterr().out
        assert "quick configuration" in printed and "seeds [0, 1]" in printed and "2 optimiser steps" in printed
        assert "| none |" in printed and "| fs-1 |" in printed and "95 %" in printed
        saved = json.loads((out / "results.json").read_text())
        _check_shape(saved, ["control"], ["none", "fs-1"], [0, 1])
        assert saved["config"]["steps"] == 2
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            assert "no figures" in printed
        else:
            assert (out / "accuracy_vs_time.png").exists()

    def test_arguments(self):
        parser = cli.build_parser()
        args = parser.parse_args(["reproduce", "--seeds", "0,4,7", "--full"])
        assert args.seeds == [0, 4, 7] and args.full and args.methods is None
        assert parser.parse_args(["reproduce", "--seeds", "0"]).seeds == [0]  # one seed: seed 0
        assert parser.parse_args(["reproduce", "--seeds", "2-4"]).seeds == [2, 3, 4]
        assert str(args.out) == "results" and args.device == "auto"
        for bad in (["reproduce", "--seeds", "1,1"], ["reproduce", "--seeds", "-1"], ["reproduce", "--steps", "-3"],
                    ["reproduce", "--hidden-channels", "a"], ["reproduce", "--device", "tpu"], []):
            with pytest.raises(SystemExit):
                parser.parse_args(bad)

    def test_plan_prints_the_cost_without_training(self, tmp_path, capsys, monkeypatch):
        monkeypatch.setattr(protocol_phases, "run_unit", lambda *a, **k: pytest.fail("--plan trained"))
        assert cli.main(["reproduce", "--plan", "--scenes", "control", "timing", "--seeds", "0-7",
                         "--steps", "100", "--group", "method", "--out", str(tmp_path)]) == 0
        printed = capsys.readouterr().out
        # control: 4 methods (no gap, so no policy rows), timing: 3 + inferred, prior, everything;
        # budget check on timing only: none + one method at 200 steps; fresh data per seed: a unit per seed
        # (with-labels beside inferred on timing, none-local on both: timing's borrows control's)
        assert "plan: 80 units to train (104 before train-once sharing), 104 members × 100 steps" in printed
        assert "of which 24 borrow the weights" in printed and "80 are trained: 8,000 member-steps" in printed
        assert "budget check of 1 gapped scene(s) at 200 steps: 16 more units (16 before sharing), 3,200" in printed
        assert "data: fresh per seed: each of the 8 seeds draws its own" in printed
        assert "total 11,200 member-steps trained" in printed and "budget check on ['timing']" in printed

    def test_help_does_not_import_torch(self):
        code = (
            "import sys, contextlib, io\n"
            "from event_transforms.tactile import cli\n"
            "with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
            "    cli.main(['--help'])\n"
            "import event_transforms\n"
            "assert 'torch' not in sys.modules, 'torch imported'\n"
        )
        subprocess.run([sys.executable, "-c", code], check=True)

    def test_quick_configuration_is_stated(self):
        help_text = cli.build_parser()._subparsers._group_actions[0].choices["reproduce"].format_help()
        help_text = " ".join(help_text.split())
        assert f"{cli.QUICK['seeds']} paired seeds" in help_text and "--full" in help_text
        assert cli.FULL["seeds"] == 10 and cli.QUICK["seeds"] >= 8  # issue 17: ≥ 8 paired seeds
        assert {"control", "paper", "timing"} <= set(cli.QUICK["scenes"]) and cli.FULL["scenes"] is None


class TestCommandLineErrors:
    """Mistakes a person makes reach them as one line naming the value, exit code 2, no traceback."""

    def _error(self, argv, capsys) -> str:
        assert cli.main(argv) == 2
        captured = capsys.readouterr()
        lines = captured.err.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in captured.err, captured.err
        return lines[0]

    def test_unknown_scene_lists_the_valid_ones(self, tmp_path, capsys):
        line = self._error(["reproduce", "--scenes", "nonexistent", "--out", str(tmp_path)], capsys)
        assert "'nonexistent'" in line and all(name in line for name in SCENES)

    def test_unknown_method_lists_the_valid_ones(self, tmp_path, capsys):
        line = self._error(["reproduce", "--scenes", "control", "--methods", "bogus", "--out", str(tmp_path)], capsys)
        assert "'bogus'" in line and "rot<deg>" in line and "tes<j>:<fraction>" in line

    def test_show_scene_more_rows_than_grasps_is_refused(self, tmp_path, capsys):
        # it used to say "50 training rows" and draw 2
        line = self._error(["show-scene", "control", "--rows", "50", "--count", "2", "--out", str(tmp_path / "o")], capsys)
        assert "--rows 50" in line and "--count 2" in line and not (tmp_path / "o").exists()

    def test_show_out_without_a_suffix_is_refused_before_simulating(self, tmp_path, capsys):
        line = self._error(["show", "none", "--root", str(tmp_path / "cache"), "--out", str(tmp_path / "picture")], capsys)
        assert "must name a .png file or an existing folder" in line and not (tmp_path / "cache").exists()

    def test_show_unknown_method_before_any_simulation(self, tmp_path, capsys):
        line = self._error(["show", "bogus", "--root", str(tmp_path / "cache"), "--out", str(tmp_path / "x.png")],
                           capsys)
        assert "'bogus'" in line and not (tmp_path / "cache").exists()
        assert "'nowhere'" in self._error(["show-scene", "nowhere", "--out", str(tmp_path)], capsys)

    def test_shift_past_the_sequence_is_refused_by_name(self, tmp_path, capsys):
        line = self._error(["reproduce", "--scenes", "control", "--methods", "fs100", "--out", str(tmp_path)], capsys)
        assert "'fs100'" in line and "36 frames" in line
        line = self._error(["reproduce", "--scenes", "control", "--methods", "rot-45", "--out", str(tmp_path)], capsys)
        assert "'rot-45'" in line and "-45" in line

    @pytest.mark.parametrize("flag", ["--out", "--root"])
    def test_unwritable_folder_is_refused_before_any_work(self, tmp_path, capsys, flag, monkeypatch):
        blocker = tmp_path / "a-file"
        blocker.write_text("")
        called = []
        monkeypatch.setattr(protocol_plan, "load_scene_data", lambda *a, **k: called.append(a))
        argv = ["reproduce", "--scenes", "control", "--methods", "none", "--out", str(tmp_path / "out")]
        line = self._error([*argv, flag, str(blocker / "sub")], capsys)
        assert flag in line and "a-file" in line and not called

    def test_zero_copies_refused_by_name(self, capsys):
        with pytest.raises(SystemExit) as exit_:
            cli.build_parser().parse_args(["reproduce", "--copies", "0"])
        assert exit_.value.code == 2 and "--copies" in capsys.readouterr().err
        with pytest.raises(ValueError, match="copies"):
            ProtocolConfig(copies=0)

    def test_worker_error_reaches_the_user_as_itself(self, scene_data, tmp_path):
        # the noise method needs the deployment camera's noise bank: the error is raised in a worker
        no_bank = {"control": SceneData(**{**scene_data["control"].__dict__, "noise_bank": None})}
        with pytest.raises(ValueError, match="noise bank"):
            run_protocol(["control"], [0], tmp_path / "r", config=TINY, methods=["none", "noise"], data=no_bank,
                         group="method", jobs=2)


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("cache")


@pytest.mark.slow
class TestCommandLineRealData:
    """show and show-scene on the simulated grasps (a few seconds to simulate a split)."""

    @pytest.mark.parametrize("method", ["fs-1", "none", "resize"])
    def test_show(self, cache, tmp_path, method, capsys):
        out = tmp_path / "grid.png"
        assert cli.main(["show", method, "--root", str(cache), "--out", str(out), "--index", "30"]) == 0
        assert out.exists() and out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert str(out) in capsys.readouterr().out

    def test_show_into_an_existing_folder_writes_inside_it(self, cache, tmp_path, capsys):
        # it used to write <folder>.png beside the folder and say it wrote the folder
        folder = tmp_path / "figures"
        folder.mkdir()
        assert cli.main(["show", "fs-1", "--root", str(cache), "--out", str(folder), "--index", "30"]) == 0
        written = folder / "fs-1.png"
        assert written.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and not (tmp_path / "figures.png").exists()
        assert f"wrote {written}" in capsys.readouterr().out

    def test_show_without_matplotlib_is_one_line(self, cache, tmp_path, capsys, monkeypatch):
        for name in [m for m in sys.modules if m == "matplotlib" or m.startswith("matplotlib.")]:
            monkeypatch.delitem(sys.modules, name)
        monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib raises ImportError
        assert cli.main(["show", "none", "--root", str(cache), "--out", str(tmp_path / "x.png")]) == 2
        err = capsys.readouterr().err
        assert "show: error: matplotlib is not installed" in err and "event-transforms[app]" in err
        assert len(err.strip().splitlines()) == 1

    def test_missing_tqdm_names_the_app_extra(self, tmp_path, capsys, monkeypatch):
        monkeypatch.setitem(sys.modules, "tqdm", None)  # import tqdm raises ImportError
        assert cli.main(["reproduce", "--out", str(tmp_path / "out"), "--root", str(tmp_path / "cache")]) == 2
        err = capsys.readouterr().err
        assert "reproduce: error: tqdm is not installed" in err and "event-transforms[app]" in err
        assert not (tmp_path / "cache").exists()  # refused before simulating anything

    def test_fit_ensemble_without_tqdm_names_the_extra(self, monkeypatch):
        from event_transforms.tactile.ensemble import EnsembleForceRegressor
        from event_transforms.tactile.training import fit_ensemble

        monkeypatch.setitem(sys.modules, "tqdm.auto", None)
        with pytest.raises(ImportError, match=r"event-transforms\[app\]") as info:
            fit_ensemble(EnsembleForceRegressor(1, hidden_channels=(2,)), [], [], steps=1, batch_size=1, seeds=[0])
        assert info.value.name == "tqdm"

    def test_show_bad_index(self, cache, tmp_path):
        with pytest.raises(SystemExit, match="index"):
            cli.main(["show", "fs-1", "--root", str(cache), "--index", "48", "--out", str(tmp_path / "x.png")])

    def test_show_scene(self, cache, tmp_path, capsys):
        assert cli.main(["show-scene", "timing", "--count", "3", "--out", str(tmp_path)]) == 0
        path = tmp_path / "scene_timing.png"
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and "deployment" in capsys.readouterr().out


def test_a_seed_does_not_depend_on_the_seeds_beside_it():
    """Issue 24: seed 0 trained alone equals seed 0 trained beside seed 1, bit for bit."""
    data = fake_data("paper")
    config = ProtocolConfig(**{**TINY.__dict__, "steps": 12, "eval_every": 4})
    alone = protocol.run_unit("paper", ["none", "rot45"], [0], config, data)
    shared = protocol.run_unit("paper", ["none", "rot45"], [0, 1], config, data)
    for method in ("none", "rot45"):
        assert alone[method][0]["test_mse"] == shared[method][0]["test_mse"]
        assert alone[method][0]["holdout_history"] == shared[method][0]["holdout_history"]


class TestEqualTime:
    """MSE at equal cost (issue 24, item 6; issue 33, item 6): each method retrained for the steps
    its cost per step (from the cost table) leaves in none's time."""

    def test_steps_from_the_timings(self):
        assert timing.equal_time_steps(300, 10.0, 20.0) == 150
        assert timing.equal_time_steps(300, 10.0, 20.0, grain=40) == 120  # rounded down
        assert timing.equal_time_steps(300, 10.0, 10.0, grain=25) == 300
        assert timing.equal_time_steps(300, 10.0, 1e6, grain=25) == 25  # never below one grain
        with pytest.raises(ValueError, match="online_wall_s"):
            timing.equal_time_steps(300, 10.0, 9.0)
        with pytest.raises(ValueError, match="online_wall_s"):
            timing.equal_time_steps(300, 10.0, float("nan"))
        with pytest.raises(ValueError, match="steps"):
            timing.equal_time_steps(0, 10.0, 20.0)

    def test_retrains_at_the_affordable_steps(self, monkeypatch, tmp_path):
        """The steps come from the cost table (issue 33, item 6): stretch costs twice a plain step,
        fs-1 nothing; the measured wall times do not enter."""
        from event_transforms.tactile.protocol.costs import COST_TABLE_FORMAT, cost_key

        # given data: each seed's bootstrap resample (no fresh data can be drawn from them)
        config = ProtocolConfig(**{**TINY.__dict__, "steps": 8, "eval_every": 4, "resample": "bootstrap"})
        data = {"paper": fake_data("paper")}
        timing = {"single_model_wall_s": {"median": 10.0, "min": 9.0, "max": 11.0, "repeats": 3},
                  "single_model_scene": "paper",
                  "online_aug_s_per_epoch": {"paper": {"none": None, "stretch": 123.0, "fs-1": 0.0}}}
        monkeypatch.setattr(protocol_phases, "measure_timing", lambda *a, **k: timing)
        commits = iter(["a" * 40, "b" * 40, "b" * 40])  # the checkout moves during the run
        monkeypatch.setattr(protocol_config, "git_commit", lambda: next(commits))
        costs = {"format": COST_TABLE_FORMAT, "config": cost_key(config),
                 "ratios": {"paper": {"none": 1.0, "stretch": 2.0, "fs-1": 1.0}}}
        results = run_protocol(["paper"], [0, 1], tmp_path, config=config, methods=["none", "stretch", "fs-1"],
                               data=data, budget_check=False, equal_time=True, cost_table=costs)
        methods = results["scenes"]["paper"]["methods"]
        assert "equal_time" not in methods["none"]
        assert methods["stretch"]["equal_time"]["steps"] == 4  # floor(8 / 2.0), whatever the stopwatch said
        direct = run_unit("paper", ["stretch"], [0, 1], ProtocolConfig(**{**config.__dict__, "steps": 4}),
                          data["paper"], progress=False)
        assert methods["stretch"]["equal_time"]["test_mse"] == [r["test_mse"] for r in direct["stretch"]]
        assert methods["stretch"]["equal_time"]["test_mse"] != methods["stretch"]["test_mse"]
        # no online cost: every step affordable, the main run is the equal-time run
        assert methods["fs-1"]["equal_time"]["steps"] == 8
        assert methods["fs-1"]["equal_time"]["test_mse"] == methods["fs-1"]["test_mse"]
        # Δ against none's main run, paired by seed, one family of two
        delta = methods["stretch"]["equal_time"]["delta_vs_none"]
        expected = paired_t(methods["none"]["test_mse"], methods["stretch"]["equal_time"]["test_mse"])
        assert delta["mean"] == pytest.approx(expected.mean) and delta["family_size"] == 2
        table = format_scene_table("paper", results["scenes"]["paper"])
        assert "Δ vs none at equal cost" in table.splitlines()[0]
        assert "| 8 (the budget) |" in table
        # the cost curve (budget check off): none at 1.5 x the steps, every method's Δ against it
        curve = results["scenes"]["paper"]["cost_curve"]
        assert curve["ratios"] == [1.0, 1.5] and curve["steps"] == {"1.0": 8, "1.5": 12}
        longer = run_unit("paper", ["none"], [0, 1], ProtocolConfig(**{**config.__dict__, "steps": 12}),
                          data["paper"], progress=False)["none"]
        point = curve["methods"]["stretch"]["1.5"]
        expected = paired_t([r["test_mse"] for r in longer], methods["stretch"]["test_mse"])
        assert point["mean"] == pytest.approx(expected.mean) and point["family_size"] == 2
        assert curve["methods"]["stretch"]["1.0"]["mean"] == pytest.approx(methods["stretch"]["delta_vs_none"]["mean"])
        assert "Δ vs none at 1.5× its steps (12)" in table.splitlines()[0]
        assert results["config"]["equal_time"] is True
        assert results["commit"] == "a" * 40  # the commit that trained, read when the run started
        pytest.importorskip("matplotlib")
        paths = figures.plot_results(results, tmp_path)
        assert tmp_path / "accuracy_at_equal_time.png" in paths
        assert (tmp_path / "accuracy_at_equal_time.png").stat().st_size > 0

    def test_off_by_default_in_run_protocol_and_full(self, tmp_path):
        plan = protocol.plan_run(["paper"], {"paper": ["none", "stretch"]}, [0, 1], TINY, equal_time=True)
        assert plan["equal_time_member_steps_max"] == 1 * 2 * TINY.steps
        assert protocol.plan_run(["paper"], {"paper": ["none"]}, [0], TINY)["equal_time_member_steps_max"] == 0
        assert cli.QUICK["equal_time"] and not cli.FULL["equal_time"]
