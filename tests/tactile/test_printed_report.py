"""The printed output of ``event-transforms reproduce``: progress lines and the report a newcomer
reads (withheld verdicts say why, counts agree, --quiet keeps the tables in view)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from event_transforms.tactile import cli
from event_transforms.tactile.protocol import plan as protocol_plan
from tests.tactile.test_cli import TINY, data, fake_data  # noqa: F401 (data: a fixture)

pytestmark = pytest.mark.usefixtures("one_thread")  # see conftest.py


class TestProgressOutput:
    """Long loops show one progress bar, not a line per item (issue 34): binning 192 recordings
    printed 192 'binned ...' lines."""

    def test_binning_recordings_prints_one_summary_line(self, tmp_path, monkeypatch, capsys):
        from types import SimpleNamespace

        from event_transforms.tactile import commands, recordings

        def fake_load(root, settings, *, cache=None, log=None, deployment=True):
            log("crop: the contact area of 4 training recordings")
            for k in range(192):
                log(f"binned events/g{k:03d}.npy: 1,000 events into 40 frames in 0.0 s")
            dataset = {"folder": str(root), "files": 384, "content_hash": "0" * 64, "recordings": {"test": 96},
                       "windows": {"test": 96}, "settings": {"stride": 36}, "crop": (0, 0, 10, 10),
                       "crop_source": "given", "left_out_frames": 0}
            return SimpleNamespace(dataset=dataset)

        monkeypatch.setattr(recordings, "load_recording_data", fake_load)
        args = cli.build_parser().parse_args(["infer-scene", "--data", str(tmp_path)])
        commands.load_recordings(args)
        lines = capsys.readouterr().out.splitlines()
        assert not [line for line in lines if line.startswith("binned ")]
        assert lines[0] == "crop: the contact area of 4 training recordings"  # other lines pass through
        assert lines[1].startswith("binning recordings: 192 recordings in ")
        assert lines[2].startswith("data: ") and len(lines) == 3

    def test_infer_scene_on_a_folder_prints_no_line_per_recording(self, tmp_path, capsys, monkeypatch):
        from tests.tactile.test_recordings import make_folder

        monkeypatch.setenv("EVENT_TRANSFORMS_CACHE", str(tmp_path / "cache"))  # bins every recording, whatever ran before
        root = make_folder(tmp_path / "d", train=6, deploy=5, unlabeled=1)
        assert cli.main(["infer-scene", "--data", str(root), "--sensor-size", "30", "40", "--frames", "12"]) == 0
        lines = capsys.readouterr().out.splitlines()
        assert not [line for line in lines if line.startswith("binned ")], lines
        assert [line for line in lines if line.startswith("binning recordings: 12 recordings in ")]

    def test_item_progress_without_items_says_nothing(self, capsys):
        from event_transforms.tactile.commands import ItemProgress

        log = ItemProgress("binned ", "binning recordings", "recordings")
        assert log.close() is None and capsys.readouterr().out == ""


class TestPrintedReport:
    """A printed report agrees with its numbers (issue 44, item 2): the plan's unit counts are the
    progress lines' k/N, every withheld verdict says why, the budget check reads the same in
    --help, docs and code, and --quiet leaves the tables unburied."""

    args = ["reproduce", "--scenes", "control", "timing", "--methods", "none", "fs2", "fs-1", "--seeds", "0,1",
            "--steps", "2", "--hidden-channels", "2", "--input-pool", "4", "--batch-size", "4", "--jobs", "1",
            "--no-plots", "--no-equal-time"]

    def test_plan_progress_and_report_agree(self, tmp_path, monkeypatch, capsys):
        monkeypatch.setattr(protocol_plan, "load_scene_data", lambda scene, root=None, **k: fake_data(scene))
        assert cli.main([*self.args, "--out", str(tmp_path / "res")]) == 0
        captured = capsys.readouterr()
        printed = captured.out
        plan = re.search(r"plan: (\d+) units to train .*?budget check of \d+ gapped scene\(s\) at \d+ steps: (\d+) "
                         r"more units", printed)
        assert plan, printed[:2000]
        units, budget = int(plan[1]), int(plan[2])
        numbered = re.findall(r"\[rank 0\] unit (\d+)/(\d+) .*: test MSE", printed)
        checked = re.findall(r"\[rank 0\] budget check (\d+)/(\d+) .*: test MSE", printed)
        assert {int(n) for _, n in numbered} == {units} and len(numbered) == units
        assert {int(n) for _, n in checked} == {budget} and len(checked) == budget > 0
        for line in printed.splitlines():
            if "shows no resolved change" in line:
                assert re.search(r"shows no resolved change \((not converged|borderline|its Bonferroni interval "
                                 r"includes 0|its Holm)", line), line
        assert "matched matched" not in printed and "budget check of the headline" in printed
        # --quiet: the same run resumed prints the plan and the tables, no per-unit or per-step lines
        assert cli.main([*self.args, "--out", str(tmp_path / "res"), "--quiet"]) == 0
        quiet = capsys.readouterr()
        assert "[rank" not in quiet.out and "[rank" not in quiet.err and "progress lines:" not in quiet.out
        assert "plan: " in quiet.out and "| none |" in quiet.out and "budget check of the headline" in quiet.out

    def test_withheld_verdicts_say_why_and_the_matched_row_reads_once(self):
        from event_transforms.tactile.report import format_findings

        delta = {"mean": -3.16, "ci_family": [-3.76, -2.56], "n": 8, "better_seeds": 8, "not_converged": True}
        vs = {"mean": 1.2, "ci_family": [0.4, 2.0], "n": 8, "better_seeds": 1, "borderline": True}
        summary = {"baselines": {}, "methods": {"fs2": {"delta_vs_none": delta, "delta_vs_matched": vs,
                                                        "matched_row": "matched", "aug_s_once": 0.1}}}
        (line,) = format_findings("timing", summary)
        assert line.startswith("timing / fs2: shows no resolved change (not converged: the side behind was still "
                               "improving at the step cap): -3.16 N²"), line
        assert ("not resolved (borderline: the interval excludes 0 but one block of seeds points the other way) from "
                "the matched row by") in line
        assert "the matched row by +1.20" in line and "matched matched" not in line

    def test_the_budget_check_reads_the_same_in_help_docs_and_code(self):
        help_text = " ".join(cli.build_parser()._subparsers._group_actions[0].choices["reproduce"].format_help()
                             .split())
        assert "pre-declared headline (its first matched method)" in help_text and "largest" not in help_text
        docs = (Path(__file__).resolve().parents[2] / "docs" / "benchmark.md").read_text()
        assert "pre-declared headline" in " ".join(docs.split())
        assert "pre-declared headline" in protocol_plan.headline.__doc__
        from event_transforms.tactile.report import format_budget_check

        assert format_budget_check(None, skipped=True) == "budget check: not run (--no-budget-check, or budget_check=False)"
