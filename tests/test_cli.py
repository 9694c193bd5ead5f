"""Tests for the protocol runner and the ``event-transforms`` command line (in-process)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
import torch

import event_transforms as et
from event_transforms.tactile import cli, protocol, training
from event_transforms.tactile.protocol import (
    PAPER_METHODS,
    MaterializedDataset,
    Method,
    ProtocolConfig,
    ProtocolData,
    build_training_set,
    format_table,
    parse_method,
    run_protocol,
)
from event_transforms.tactile.training import Stopwatch
from tests.test_training import FakeGrasps


pytestmark = pytest.mark.usefixtures("one_thread")  # see conftest.py


TINY = ProtocolConfig(epochs=2, patience=1, batch_size=4, hidden_channels=(2,), input_pool=4)


def fake_data() -> ProtocolData:
    g = torch.Generator().manual_seed(9)
    bank = torch.poisson(torch.full((40, 2, 16, 12), 0.2), generator=g)
    return ProtocolData(
        FakeGrasps(6, seed=1), FakeGrasps(3, diameters=(15.0,), seed=2),
        FakeGrasps(3, diameters=(15.0,), seed=3), bank, "fake grasps",
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

    @pytest.mark.parametrize("name", ["", "rot", "fs", "tes-2", "tes-2:", "fs-1x", "blur", "tes-1:1.5"])
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
        assert [type(t) for t in method.build().transforms] == [et.ResizeToTarget, et.RandomRotation]
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
            torch.testing.assert_close(frames, et.Resize(15.0 / meta["diameter_mm"])(original))


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


class TestRunProtocol:
    def test_results_and_table(self, data, tmp_path):
        results = run_protocol(["none", "fs-1", "noise"], [0, 1], tmp_path, config=TINY, data=data)
        saved = json.loads((tmp_path / "results.json").read_text())
        assert list(saved["methods"]) == ["none", "fs-1", "noise"]
        summary = saved["methods"]["fs-1"]
        assert summary["best_val_mse"]["values"] == [r["best_val_mse"] for r in saved["per_seed"]["fs-1"]]
        assert summary["train_items"] == 12 and summary["copies"] == 1
        assert set(summary["test_phase_mse"]) == {"grasp", "hold", "release"}
        # Fixed copies are made once before training: their cost is "aug once".
        assert summary["augmentation_setup_s"]["mean"] > 0
        assert summary["augmentation_s_per_epoch"]["mean"] == 0
        assert saved["methods"]["none"]["augmentation_setup_s"]["mean"] == 0
        table = (tmp_path / "results.md").read_text()
        assert table.strip() == format_table(results.methods)
        lines = table.strip().splitlines()
        assert len(lines) == 5 and lines[2].startswith("| none | 0 |")
        assert "Δ vs none" in lines[0] and "aug ms/epoch" in lines[0] and " %" in lines[3]
        assert "aug ms once" in lines[0]
        assert "train s" not in format_table(results.methods, timings=False)

    def test_resume_after_interruption_gives_same_table(self, data, tmp_path, monkeypatch):
        methods, seeds = ["none", "resize"], [0, 1]
        clean = run_protocol(methods, seeds, tmp_path / "clean", config=TINY, data=data)

        real_fit, calls = training.fit, []

        def killed_after_three(*args, **kwargs):
            calls.append(kwargs["seed"])
            if len(calls) == 4:
                raise KeyboardInterrupt  # killed between resize seed 0 and seed 1
            return real_fit(*args, **kwargs)

        monkeypatch.setattr(protocol, "fit", killed_after_three)
        with pytest.raises(KeyboardInterrupt):
            run_protocol(methods, seeds, tmp_path / "resumed", config=TINY, data=data)
        monkeypatch.setattr(protocol, "fit", real_fit)
        resumed = run_protocol(methods, seeds, tmp_path / "resumed", config=TINY, data=data)
        assert format_table(resumed.methods, timings=False) == format_table(clean.methods, timings=False)
        for name in methods:
            for a, b in zip(resumed.per_seed[name], clean.per_seed[name]):
                assert a["best_val_mse"] == b["best_val_mse"] and a["test_mse"] == b["test_mse"]

    def test_online_augmentation_is_timed_per_epoch(self, data, tmp_path):
        online = ProtocolConfig(**{**TINY.__dict__, "fixed": False})
        results = run_protocol(["rot45"], [0], tmp_path, config=online, data=data)
        run = results.per_seed["rot45"][0]
        assert run["augmentation_setup_s"] == 0 and run["augmentation_s_per_epoch"] > 0
        assert all(h["augmentation_s"] > 0 for h in run["history"])

    def test_other_settings_do_not_reuse_results(self, data, tmp_path):
        run_protocol(["none"], [0], tmp_path, config=TINY, data=data)
        other = ProtocolConfig(**{**TINY.__dict__, "epochs": 1})
        results = run_protocol(["none"], [0], tmp_path, config=other, data=data)
        assert results.per_seed["none"][0]["epochs_run"] == 1
        assert len(list((tmp_path / "runs").iterdir())) == 2

    def test_duplicate_names(self, data, tmp_path):
        with pytest.raises(ValueError, match="distinct"):
            run_protocol(["none", "none"], [0], tmp_path, config=TINY, data=data)


class TestCommandLine:
    def test_reproduce_smoke(self, data, tmp_path, monkeypatch, capsys):
        monkeypatch.setattr(protocol, "load_data", lambda root=None: data)
        out = tmp_path / "res"
        code = cli.main([
            "reproduce", "--methods", "none", "fs-1", "--seeds", "2", "--epochs", "2",
            "--patience", "1", "--hidden-channels", "2", "--batch-size", "4", "--out", str(out),
        ])
        assert code == 0
        printed = capsys.readouterr().out
        assert "quick configuration" in printed and "seeds [0, 1]" in printed
        assert "| none | 0 |" in printed and "| fs-1 | 1 |" in printed
        saved = json.loads((out / "results.json").read_text())
        assert saved["config"]["epochs"] == 2 and saved["seeds"] == [0, 1]
        assert (out / "results.md").exists()
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            assert "no figures" in printed
        else:
            assert (out / "mse_vs_time.png").exists() and (out / "predictions.png").exists()

    def test_arguments(self):
        parser = cli.build_parser()
        args = parser.parse_args(["reproduce", "--seeds", "0,4,7", "--full"])
        assert args.seeds == [0, 4, 7] and args.full and args.methods is None  # the paper's list
        assert str(args.out) == "results"
        for bad in (["reproduce", "--seeds", "0"], ["reproduce", "--seeds", "1,1"],
                    ["reproduce", "--epochs", "-3"], ["reproduce", "--hidden-channels", "a"], []):
            with pytest.raises(SystemExit):
                parser.parse_args(bad)

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
        assert f"{cli.QUICK['seeds']} seeds" in help_text and "--full" in help_text
        assert cli.FULL["seeds"] == 10 and cli.FULL["patience"] == 20


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("cache")


@pytest.mark.slow
class TestCommandLineRealData:
    """simulate and show on the simulated grasps (a few seconds to simulate once)."""

    def test_simulate(self, cache, capsys):
        assert cli.main(["simulate", "--root", str(cache)]) == 0
        printed = capsys.readouterr().out
        assert "'train': 48" in printed and "'val': 6" in printed and "(360, 2, 70, 75)" in printed
        assert any(cache.iterdir())

    @pytest.mark.parametrize("method", ["fs-1", "none", "resize"])
    def test_show(self, cache, tmp_path, method, capsys):
        out = tmp_path / "grid.png"
        assert cli.main(["show", method, "--root", str(cache), "--out", str(out), "--index", "30"]) == 0
        assert out.exists() and out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert str(out) in capsys.readouterr().out

    def test_show_bad_index(self, cache, tmp_path):
        with pytest.raises(SystemExit, match="index"):
            cli.main(["show", "fs-1", "--root", str(cache), "--index", "48", "--out", str(tmp_path / "x.png")])
