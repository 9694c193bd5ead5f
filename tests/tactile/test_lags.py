"""Lags from labelled recordings: recording_lags and session_lag against
synthetic recordings with a known lag, infer_scene's timing test from them, the protocol's
``inferred`` policy and ``reproduce --data`` on an exported scene."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from event_transforms.inference import infer_scene
from event_transforms.tactile.lags import infer_scene_with_lags, recording_lags, session_lag

FRAME_MS = 10.0


def _recordings(n: int, lag_ms: float, *, seed: int, tau_ms: float = 0.0, frames: int = 36, noise: float = 0.3,
                polarity: int = 1) -> tuple[torch.Tensor, torch.Tensor]:
    """``n`` grasps: force read at the frame centres, and OFF/ON counts of a strip whose half-width
    follows √ of the membrane force (first-order lag ``tau_ms``) ``lag_ms`` late, plus Poisson noise."""
    rng = np.random.default_rng(seed)
    fine = np.arange(frames * 100 + 1) * FRAME_MS / 100  # 0.1 ms grid
    all_frames, all_forces = [], []
    for _ in range(n):
        start, ramp = rng.uniform(20, 80), rng.uniform(25, 75)
        end = rng.uniform(frames * FRAME_MS - 90, frames * FRAME_MS - 40)
        hold = rng.uniform(1, 24)
        up = np.clip(np.minimum((fine - start) / ramp, (end - fine) / ramp), 0, 1)
        force = hold * (0.5 - 0.5 * np.cos(np.pi * up))  # smooth ramps, as a gripper closes
        membrane = force.copy()
        if tau_ms > 0:
            a = 1 - math.exp(-(fine[1] - fine[0]) / tau_ms)
            for k in range(1, len(fine)):
                membrane[k] = membrane[k - 1] + a * (force[k] - membrane[k - 1])
        width = 40 * np.sqrt(np.interp(fine - lag_ms, fine, membrane))  # the strip's edge length × half-width
        edges = width[::100]
        change = np.diff(edges)  # per frame
        off = rng.poisson(np.clip(change, 0, None) + noise)
        on = rng.poisson(np.clip(-change, 0, None) + noise)
        if polarity < 0:
            off, on = on, off
        f = torch.zeros(frames, 2, 3, 3)
        f[:, 0, 1, 1], f[:, 1, 1, 1] = torch.from_numpy(off).float(), torch.from_numpy(on).float()
        all_frames.append(f)
        all_forces.append(torch.from_numpy(force[50::100][:frames]).float())  # at the frame centres
    return torch.stack(all_frames), torch.stack(all_forces)


class TestRecordingLags:
    @pytest.mark.parametrize("lag", [0.0, 7.0, 23.0, -12.0])
    def test_a_known_delay_within_3_ms_mostly_and_2_ms_median(self, lag):
        frames, forces = _recordings(12, lag, seed=int(lag) + 100)
        lags = recording_lags((frames, forces), frame_ms=FRAME_MS)
        assert float(((lags["lag_ms"] - lag).abs() < 3.0).double().mean()) >= 0.8, lags["lag_ms"]
        assert session_lag(lags["lag_ms"])["median"] == pytest.approx(lag, abs=2.0)
        assert bool((lags["correlation"] > 0.9).all()) and not bool(lags["at_edge"].any())

    def test_a_slow_membrane_counts_its_time_constant(self):
        """A first-order lag τ delays a ramp by τ: the lag is delay + τ within 2 ms (a plain
        cross-correlation peak would say about 0.7 τ + delay)."""
        frames, forces = _recordings(12, 4.0, seed=3, tau_ms=15.0)
        lags = recording_lags((frames, forces), frame_ms=FRAME_MS)
        assert session_lag(lags["lag_ms"])["median"] == pytest.approx(19.0, abs=2.0)

    def test_polarity_does_not_matter(self):
        frames, forces = _recordings(6, 12.0, seed=4)
        flipped = recording_lags((frames.flip(2), forces))
        straight = recording_lags((frames, forces))
        assert torch.allclose(flipped["lag_ms"], straight["lag_ms"])
        assert bool((flipped["correlation"] < 0).all()) and bool((straight["correlation"] > 0).all())

    def test_recordings_of_different_lengths(self):
        a, fa = _recordings(3, 10.0, seed=5, frames=36)
        b, fb = _recordings(3, 10.0, seed=6, frames=30)
        lags = recording_lags((list(a) + list(b), list(fa) + list(fb)))
        assert lags["lag_ms"].shape == (6,) and float((lags["lag_ms"] - 10.0).abs().max()) < 4.0

    def test_a_steady_force_has_no_lag_and_is_counted(self):
        frames, forces = _recordings(3, 10.0, seed=7)
        forces[1] = 5.0  # a window of a steady hold
        lags = recording_lags((frames, forces))
        assert math.isnan(float(lags["lag_ms"][1])) and not math.isnan(float(lags["lag_ms"][0]))
        summary = session_lag(lags["lag_ms"])
        assert summary["n"] == 2 and summary["uninformative"] == 1

    def test_session_lag_against_the_definition(self):
        values = torch.tensor([3.0, 1.0, 7.0, 2.0, 100.0])
        summary = session_lag(values)
        assert summary["median"] == 3.0
        assert summary["spread"] == pytest.approx(1.4826 * 2.0)  # deviations 0, 1, 2, 4, 97
        assert summary["se"] == pytest.approx(math.sqrt(math.pi / 2) * summary["spread"] / math.sqrt(5))
        one = session_lag(torch.tensor([4.0]))
        assert one["n"] == 1 and one["se"] == 0.0
        assert session_lag(torch.tensor([math.nan]))["n"] == 0

    @pytest.mark.parametrize(
        "labelled, error, match",
        [
            ((torch.zeros(2, 8, 2, 3, 3), torch.zeros(2, 7)), ValueError, "recording 0 has 8 frames but 7 force"),
            ((torch.zeros(2, 8, 2, 3, 3), torch.zeros(3, 8)), ValueError, "2 recordings of frames but 3 of forces"),
            ((torch.zeros(2, 8, 2, 3, 3),), TypeError, "must be a pair"),
            ((torch.zeros(2, 8, 3, 3, 3), torch.zeros(2, 8)), ValueError, "expected"),
            ((torch.zeros(2, 8, 2, 3, 3), torch.full((2, 8), math.nan)), ValueError, "NaN or Inf forces"),
            ((torch.zeros(2, 2, 2, 3, 3), torch.zeros(2, 2)), ValueError, "at least 3"),
            (("frames", torch.zeros(2, 8)), TypeError, "labelled frames must be"),
        ],
    )
    def test_bad_input(self, labelled, error, match):
        with pytest.raises(error, match=match):
            recording_lags(labelled)

    def test_bad_settings(self):
        frames, forces = _recordings(2, 0.0, seed=8)
        with pytest.raises(ValueError, match="max_lag_ms"):
            recording_lags((frames, forces), max_lag_ms=0)
        with pytest.raises(ValueError, match="frame_ms"):
            recording_lags((frames, forces), frame_ms=-1.0)
        with pytest.raises(TypeError, match="lags must be"):
            session_lag([1.0, 2.0])  # type: ignore[arg-type]


def _scene_inputs(lag_train: float, lag_deploy: float, n_train: int = 12, n_deploy: int = 8):
    train = _recordings(n_train, lag_train, seed=11)
    deploy = _recordings(n_deploy, lag_deploy, seed=12)
    return train, deploy


class TestInferScene:
    def test_a_two_frame_gap_from_labels(self):
        (tf, tF), (df, dF) = _scene_inputs(5.0, 25.0)
        scene = infer_scene_with_lags(tf, df, labelled_train=(tf, tF), labelled_deploy=(df, dF))
        timing = scene.evidence["timing"]
        assert timing["source"] == "labelled recordings" and timing["statistic"] == "lag_ms"
        assert timing["difference"] == pytest.approx(20.0, abs=1.5) and timing["gap"]
        assert scene.lag_shifts == (2,) and scene.lag_fraction is None
        assert "onset_ms" == timing["onset"]["statistic"]  # the unlabeled test, reported beside it
        assert len(timing["lags"]["train"]["lag_ms"]) == 12 and scene.evidence["verdicts"]["timing"] == "gap"

    def test_zero_lag_difference_declares_nothing(self):
        (tf, tF), (df, dF) = _scene_inputs(6.0, 6.0)
        scene = infer_scene_with_lags(tf, df, labelled_train=(tf, tF), labelled_deploy=(df, dF))
        assert "timing" not in scene.gaps and scene.lag_shifts is None
        assert abs(scene.evidence["timing"]["difference"]) < 1.0

    def test_a_single_labelled_recording_a_side_is_not_resolvable(self):
        (tf, tF), (df, dF) = _scene_inputs(5.0, 25.0)
        scene = infer_scene_with_lags(tf, df, labelled_train=(tf[:1], tF[:1]), labelled_deploy=(df[:1], dF[:1]))
        timing = scene.evidence["timing"]
        assert timing["statistic"] == "onset_ms" and not timing["alternative"]["resolvable"]
        assert "labelled lags not resolvable from 1 training and 1 deployment labelled recordings" in \
            scene.evidence["verdicts"]["timing"]

    def test_without_labels_nothing_changes(self):
        (tf, tF), (df, dF) = _scene_inputs(5.0, 25.0)
        plain = infer_scene(tf, df)
        assert plain.evidence["timing"]["statistic"] == "onset_ms" and "alternative" not in plain.evidence["timing"]

    def test_the_library_takes_a_timing_test_from_anywhere(self):
        (tf, tF), (df, dF) = _scene_inputs(5.0, 25.0)
        from event_transforms.tactile.lags import lag_test
        test = lag_test((tf, tF), (df, dF))
        assert infer_scene(tf, df, timing=test).lag_shifts == (2,)
        with pytest.raises(TypeError, match=r"timing must be a mapping .* without \['source'\]"):
            infer_scene(tf, df, timing={k: v for k, v in test.items() if k != "source"})

    def test_bad_labelled_input(self):
        (tf, tF), (df, dF) = _scene_inputs(5.0, 5.0)
        with pytest.raises(ValueError, match="labelled_train needs labelled_deploy"):
            infer_scene_with_lags(tf, df, labelled_train=(tf, tF))
        with pytest.raises(ValueError, match="labelled_deploy: recording 0 has frames of"):
            infer_scene_with_lags(tf, df, labelled_train=(tf, tF), labelled_deploy=(df[:, :, :, :2], dF))
        with pytest.raises(ValueError, match="labelled_train: recording 0 has 36 frames but 35"):
            infer_scene_with_lags(tf, df, labelled_train=(tf, tF[:, :35]), labelled_deploy=(df, dF))


@pytest.mark.slow
class TestBenchmarkScenes:
    """The protocol's ``inferred`` on the built-in scenes: the matched rows' shifts, and no
    shift where the scene has no timing gap."""

    def test_inferred_shift_is_the_matched_rows(self):
        from event_transforms.tactile.methods import parse_method
        from event_transforms.tactile.policies import inferred_scene
        from event_transforms.tactile.benchmark_scenes import get_scene
        from event_transforms.transforms import RandomFrameShift

        for name, matched in (("paper-offset", "fs-1"), ("paper-membrane", "fs1"), ("timing", "fs2")):
            scene = inferred_scene(name)
            shift = parse_method(matched, scene=name).build().shift  # type: ignore[union-attr]
            assert scene.lag_shifts == (shift,) == (get_scene(name).lag_frames,) and scene.lag_fraction is None, name
            lag = [t for t in scene.policy("independent").transforms if isinstance(t, RandomFrameShift)]
            assert len(lag) == 1 and tuple(lag[0].shifts) == (shift,), name
            assert "timing" in scene.gaps and scene.evidence["timing"]["source"] == "labelled recordings"
        for name in ("paper", "control", "orientation"):
            scene = inferred_scene(name)
            assert "timing" not in scene.gaps and scene.lag_shifts is None, name

    def test_inferred_is_the_matched_policy_on_the_two_gap_scenes(self):
        """Done-when of issue 33: ``inferred`` equals the matched row on ``paper-offset`` and
        ``paper-membrane``: the built policies are the same (so the protocol trains them once
        and prints ``= row matched``); the single-gap timing scene's is its matched ``fs2``."""
        from event_transforms.tactile.methods import methods_for, parse_method
        from event_transforms.tactile.policies import build_policy

        for name in ("paper-offset", "paper-membrane"):
            assert "matched" in methods_for(name)
            matched = parse_method("matched", scene=name).build()
            inferred = build_policy("inferred", name)
            assert repr(inferred) == repr(matched), name
            kinds = [type(t).__name__ for t in matched.transforms]  # type: ignore[union-attr]
            assert kinds == ["RandomFrameShift", "StretchToTarget"], name

    def test_the_onset_offset_on_no_delay_scenes_is_the_start_draw(self):
        """The onset differs by about +4.5 ms on scenes without a delay because the validation
        grasps start later; the lags, measured against the force, do not."""
        from event_transforms.tactile.datasets import TactileGrasps
        from event_transforms.tactile.policies import inferred_scene
        from event_transforms.tactile.simulation import draw_grasp

        scene = inferred_scene("control")
        onset = scene.evidence["timing"]["onset"]["difference"]
        starts = []
        for split in ("train", "val"):
            data = TactileGrasps(split, scene="control")
            starts.append(np.mean([draw_grasp(15.0, seed=data.meta(i)["seed"], config=data.config).grasp_start_ms
                                   for i in range(len(data))]))
        assert onset == pytest.approx(starts[1] - starts[0], abs=1.5) and onset > 3.0
        assert abs(scene.evidence["timing"]["difference"]) < 1.0


@pytest.mark.slow
def test_reproduce_data_on_an_exported_scene_infers_the_matched_shift(tmp_path, monkeypatch):
    from event_transforms.tactile import datasets, recordings

    monkeypatch.setattr(datasets, "SPLIT_SIZES", {"train": 48, "holdout": 2, "val": 24, "test": 2})
    recordings.export_scene("paper-offset", tmp_path / "export")
    data = recordings.load_recording_data(tmp_path / "export", cache=tmp_path / "c")
    inferred = data.scene.inferred
    assert set(data.scene.gaps) == {"timing", "size"} and inferred.lag_shifts == (-1,)
    assert inferred.evidence["timing"]["train"]["n"] == 48 and inferred.evidence["timing"]["deploy"]["n"] == 24
    assert "lags from 48 training and 24 validation recordings" in data.dataset["inferred_from"]
    # the policy inferred from the exported recordings is the built-in scene's matched policy
    from event_transforms.tactile.methods import parse_method

    assert repr(inferred.policy("independent")) == repr(parse_method("matched", scene="paper-offset").build())
    with pytest.raises(ValueError, match="made of recordings, whose gaps are only inferred"):
        parse_method("matched", scene=data.scene)


def test_the_small_sample_warning_points_at_the_callers_line_through_the_wrapper():
    """``infer_scene_with_lags`` warns as ``infer_scene`` does, at the user's line (the package's
    one mechanism, ``warn_at_caller``), not at the wrapper's."""
    import warnings

    from event_transforms.inference import SmallSampleWarning

    frames = torch.poisson(torch.full((4, 12, 2, 8, 8), 0.1), generator=torch.Generator().manual_seed(0))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        infer_scene_with_lags(frames, frames.clone())
    small = [w for w in caught if issubclass(w.category, SmallSampleWarning)]
    assert len(small) == 1 and small[0].filename == __file__
