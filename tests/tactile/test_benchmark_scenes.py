"""Benchmark scenes: each declared gap exists in the simulator's output with its configured size.

Measured from simulated events (background noise switched off where it would only blur the
measurement), not from the settings.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from event_transforms.tactile.benchmark_scenes import BASE_SESSION, FACTORS, SCENES, BenchmarkScene, Session, get_scene
from event_transforms.tactile.simulation import simulate_grasps, simulate_static

QUIET = {"shot_noise": False, "hot_pixels": False}


def _recordings(session: Session, n: int, seed: int = 0, **changes):
    session = session.replace(**changes)
    return simulate_grasps(session.grasps(n, seed=seed), session.config)


class TestDeclarations:
    def test_gaps_of_every_scene(self):
        expected = {
            "paper": ("size",), "size-extrapolation": ("size",), "timing": ("timing",),
            "orientation": ("orientation",), "noise": ("noise",), "control": (),
            "paper-offset": ("size", "timing"), "paper-membrane": ("size", "timing"),
            "paper-lag": ("size", "timing"), "paper-lag-only": ("size",),
        }
        assert {name: scene.gaps for name, scene in SCENES.items()} == expected
        for scene in SCENES.values():
            assert all(m for m in scene.matched_methods)
            assert bool(scene.gaps) == bool(scene.matched_methods)

    def test_gap_specification_is_checked(self):
        with pytest.raises(ValueError, match="factor"):
            BenchmarkScene.from_gaps("x", "", BASE_SESSION, {"weather": {"delay_ms": (1.0, 2.0)}})
        with pytest.raises(ValueError, match="belong"):
            BenchmarkScene.from_gaps("x", "", BASE_SESSION, {"noise": {"delay_ms": (1.0, 2.0)}})
        with pytest.raises(ValueError, match="scene"):
            get_scene("nowhere")
        with pytest.raises(ValueError, match="diameters"):
            Session((), BASE_SESSION.config)
        assert sum(len(v) for v in FACTORS.values()) == len(set().union(*FACTORS.values()))

    def test_library_policies_build_the_matched_transforms(self):
        import event_transforms as et

        def kinds(name, bank=None):
            return [type(t) for t in get_scene(name).library_scene(bank).policy().transforms]

        assert kinds("paper") == [et.ResizeToTarget]
        assert kinds("timing") == [et.RandomFrameShift]
        assert kinds("orientation") == [et.RandomRotation]
        assert kinds("noise", torch.zeros(4, 2, 70, 75)) == [et.AddNoise]
        assert get_scene("control").library_scene().effects == ()
        assert get_scene("timing").lag_frames == 2 and get_scene("orientation").orientation_range_deg == 50.0


class TestMeasuredGaps:
    def test_timing_gap(self):
        """Events start later in deployment by the drawn difference of delays (±0.5 ms)."""
        scene = get_scene("timing")
        train = _recordings(scene.train, 4, **QUIET)
        deploy = _recordings(scene.deploy, 4, **QUIET)
        for a, b in zip(train, deploy):
            onset = (b.events["t"][0] - a.events["t"][0]) / 1000.0
            assert onset == pytest.approx(b.grasp.delay_ms - a.grasp.delay_ms, abs=1.0)
            assert 12.0 <= onset <= 24.0
            assert np.array_equal(a.force, b.force)  # the label is not delayed

    def test_size_gap(self):
        """Contact events grow as the Hertz strip width, √D: 18 mm / 12 mm ≈ √1.5."""
        scene = get_scene("size-extrapolation")
        small = _recordings(scene.train.replace(diameters_mm=(12.0,)), 6, **QUIET)
        large = _recordings(scene.deploy, 6, **QUIET)
        ratio = sum(len(r.events) for r in large) / sum(len(r.events) for r in small)
        assert ratio == pytest.approx(math.sqrt(1.5), rel=0.06)
        assert {r.grasp.diameter_mm for r in large} == {18.0}

    def test_orientation_gap(self):
        """The strip's axis, measured from the events, lies within ±10° in training and
        30–50° away from horizontal in deployment."""
        scene = get_scene("orientation")

        def axis_deg(recording):
            e = recording.events
            x, y = e["x"].astype(float), e["y"].astype(float)
            cov = np.cov(np.stack([x - x.mean(), -(y - y.mean())]))
            vals, vecs = np.linalg.eigh(cov)
            major = vecs[:, np.argmax(vals)]
            return math.degrees(math.atan2(major[1], major[0]))

        for recording in _recordings(scene.train, 6, **QUIET):
            measured = (axis_deg(recording) + 90) % 180 - 90
            assert abs(measured - recording.grasp.angle_deg) < 3.0 and abs(measured) <= 13.0
        signs = set()
        for recording in _recordings(scene.deploy, 6, **QUIET):
            measured = (axis_deg(recording) + 90) % 180 - 90
            assert abs(measured - recording.grasp.angle_deg) < 3.0 and 27.0 <= abs(measured) <= 53.0
            signs.add(measured > 0)
        assert signs == {True, False}

    def test_noise_gap(self):
        """The deployment camera's static background is about 3× the training camera's, with
        10× the hot pixels."""
        scene = get_scene("noise")
        rates = []
        for session in (scene.train, scene.deploy):
            events = simulate_static(2000.0, seed=0, config=session.config.replace(hot_pixels=False))
            rates.append(len(events) / (180 * 240 * 2.0))
        assert rates[1] / rates[0] == pytest.approx(3.0, rel=0.1)
        hot = []
        for session in (scene.train, scene.deploy):
            events = simulate_static(500.0, seed=0, config=session.config.replace(shot_noise=False))
            pixels, counts = np.unique(events["y"].astype(int) * 240 + events["x"], return_counts=True)
            hot.append(int((counts >= 10).sum()))
        # each pixel is hot with probability hot_pixel_fraction (10x in deployment): binomial counts
        # around 4.3 and 43 on 180 x 240 pixels, exactly the cameras' hot pixels
        from event_transforms.tactile import simulation

        drawn = [int((simulation._sensor(s.config.replace(shot_noise=False))[2] > 0).sum()) for s in (scene.train, scene.deploy)]
        assert hot == drawn and 1 <= hot[0] <= 10 and 25 <= hot[1] <= 65
        assert scene.deploy.config.hot_pixel_fraction == pytest.approx(10 * scene.train.config.hot_pixel_fraction)

    def test_control_deployment_is_drawn_like_training(self):
        scene = get_scene("control")
        assert scene.train == scene.deploy and scene.gaps == ()
        # independent draws of one session: event totals and forces agree within their spread
        a = _recordings(scene.train, 12, seed=0)
        b = _recordings(scene.deploy, 12, seed=500)
        for stat in (lambda r: len(r.events), lambda r: float(r.force.max())):
            x, y = np.array([stat(r) for r in a]), np.array([stat(r) for r in b])
            spread = math.sqrt(x.var(ddof=1) / len(x) + y.var(ddof=1) / len(y))
            assert abs(x.mean() - y.mean()) < 3 * spread

    def test_every_description_names_its_physics(self):
        """Each gapped scene's description names the simulator effect behind its gap."""
        words = {"paper": "sqrt(D)", "size-extrapolation": "sqrt(D)", "timing": "transport delay",
                 "orientation": "contact axis", "noise": "shot-noise", "paper-offset": "clock offset",
                 "paper-membrane": "membrane", "paper-lag": "low-pass", "paper-lag-only": "no clock offset"}
        for name, word in words.items():
            assert word in get_scene(name).description, name
        for scene in SCENES.values():  # the base jitter everywhere (issue 24)
            for session in (scene.train, scene.deploy):
                assert session.config.timing_jitter_ms == BASE_SESSION.config.timing_jitter_ms, scene.name

    def test_membrane_scene_lags_for_a_stated_reason(self):
        """paper-membrane: only the membrane's time constants differ (slower creep, slower
        release in deployment); no clock offset; the deployment's release events come later."""
        scene = get_scene("paper-membrane")
        assert scene.gap_sizes()["timing"] == {"lag_ms": ((2.0, 8.0), (10.0, 20.0)), "release_lag_ratio": (1.0, 3.0)}
        assert scene.lag_frames == 1 and scene.matched_methods == ("fs1", "tes1:0.5")
        train = _recordings(scene.train, 4, diameters_mm=(15.0,), **QUIET)
        deploy = _recordings(scene.deploy, 4, **QUIET)
        for a, b in zip(train, deploy):
            on_a, on_b = a.events["t"][a.events["p"] == 1], b.events["t"][b.events["p"] == 1]
            assert np.median(on_b) > np.median(on_a)

    def test_lag_scene_offset(self):
        """paper-offset: deployment events start earlier than training events by the drawn
        difference of delays (same seeds, same bolt), about one frame."""
        scene = get_scene("paper-offset")
        train = _recordings(scene.train, 4, diameters_mm=(15.0,), **QUIET)
        deploy = _recordings(scene.deploy, 4, **QUIET)
        for a, b in zip(train, deploy):
            onset = (b.events["t"][0] - a.events["t"][0]) / 1000.0
            assert onset == pytest.approx(b.grasp.delay_ms - a.grasp.delay_ms, abs=1.0)
            assert -18.0 <= onset <= -8.0
        assert scene.lag_frames == -1 and scene.matched_methods == ("fs-1", "tes-2:0.5")

    def test_lag_scene_membrane_releases_slowly(self):
        """With the release time constant 3× the press one, the release's ON events come later
        (and fewer of them fall inside the recording, which ends soon after the release); the
        press's OFF events do not move."""
        scene = get_scene("paper-lag")
        slow = _recordings(scene.deploy, 6, **QUIET)
        fast = _recordings(scene.deploy, 6, release_lag_ratio=1.0, **QUIET)
        for a, b in zip(slow, fast):
            on_a, on_b = a.events["t"][a.events["p"] == 1], b.events["t"][b.events["p"] == 1]
            off_a, off_b = a.events["t"][a.events["p"] == 0], b.events["t"][b.events["p"] == 0]
            assert len(on_a) < len(on_b)  # the membrane has not recovered by the end
            assert np.median(on_a) >= np.median(on_b)
            assert abs(len(off_a) - len(off_b)) <= 0.01 * len(off_b)  # pressing is unchanged
            assert abs(np.median(off_a) - np.median(off_b)) <= 1000

    def test_lag_scene_label_is_low_passed(self):
        """The F/T label is the force through a 15 ms first-order low-pass: its centre of
        mass in time comes about 15 ms after the true force's."""
        scene = get_scene("paper-lag")
        labelled = _recordings(scene.deploy, 4, **QUIET)
        true = _recordings(scene.deploy, 4, label_lowpass_ms=0.0, **QUIET)
        t = (np.arange(36) + 0.5) * 10.0
        for a, b in zip(labelled, true):
            delay = (t * a.force).sum() / a.force.sum() - (t * b.force).sum() / b.force.sum()
            assert 10.0 <= delay <= 16.0
            assert np.array_equal(a.events, b.events)  # the events do not see the label's filter

    def test_force_is_continuous_and_varied(self):
        grasps = BASE_SESSION.grasps(40, seed=0)
        holds = np.array([g.hold_force_n for g in grasps])
        assert holds.min() < 4 and holds.max() > 20 and len(np.unique(holds.round(1))) > 30
        assert np.ptp([g.grasp_ms for g in grasps]) > 30 and np.ptp([g.grasp_start_ms for g in grasps]) > 30
        assert np.ptp([g.hold_drift for g in grasps]) > 0.3
