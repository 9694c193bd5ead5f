"""The simulator reproduces its physics, measured from its own output."""

from __future__ import annotations

import math
import numpy as np
import pytest
import torch

from event_transforms.tactile import simulation
from event_transforms.functional.affine import resize
from event_transforms.tactile.simulation import (
    EVENT_DTYPE,
    SimulatorConfig,
    contact_half_width,
    draw_grasp,
    membrane_force,
    simulate_grasp,
    simulate_grasps,
    simulate_static,
)

# Contact only, strip horizontal at the sensor centre, every experiment at its nominal force.
CLEAN = SimulatorConfig(
    orientation=False,
    center_jitter_px=0.0,
    shot_noise=False,
    hot_pixels=False,
    force_variation=0.0,
    vibration=False,
)
CENTER_Y = (180 - 1) / 2


def half_width(events: np.ndarray, config: SimulatorConfig = CLEAN) -> float:
    """Strip half-width b estimated from where events fall across a horizontal strip.

    Every pixel the edge sweeps past fires about equally often, so |y - centre| of the
    events is uniform on [0, b - edge/2]: b ≈ 2·mean + edge/2.
    """
    return 2 * float(np.abs(events["y"] - CENTER_Y).mean()) + config.edge_px / 2


def frames_half_width(frames: torch.Tensor) -> float:
    """The same estimate from frames (T, 2, H, W) of a horizontal strip."""
    weight = frames.sum(dim=(0, 1, 3), dtype=torch.float64)
    rows = torch.arange(weight.numel(), dtype=torch.float64)
    centre = (weight * rows).sum() / weight.sum()
    return float(((rows - centre).abs() * weight).sum() / weight.sum())


class TestConfig:
    @pytest.mark.parametrize(
        "changes, match",
        [
            (dict(contrast=1.0), "contrast"),
            (dict(substep_ms=3.0), "multiple"),
            (dict(threshold=0.0), "threshold"),
            (dict(lag_ms=(5.0, 1.0)), "lag_ms"),
            (dict(gripper_force_n=(0.0,)), "gripper_force_n"),
            (dict(shot_noise_hz=(0.0, 1.0)), "shot_noise_hz"),
        ],
    )
    def test_bad_settings_raise(self, changes, match):
        with pytest.raises(ValueError, match=match):
            SimulatorConfig(**changes)

    def test_replace_and_duration(self):
        config = SimulatorConfig().replace(n_frames=10)
        assert config.n_frames == 10 and config.duration_ms == 100.0


class TestDrawGrasp:
    def test_deterministic_and_independent_of_bolt(self):
        a = draw_grasp(12.0, gripper=0, seed=5)
        b = draw_grasp(18.0, gripper=0, seed=5)
        assert a == draw_grasp(12.0, gripper=0, seed=5)
        assert (a.lag_ms, a.angle_deg, a.center_yx, a.hold_force_n) == (
            b.lag_ms, b.angle_deg, b.center_yx, b.hold_force_n
        )
        assert draw_grasp(12.0, seed=6) != a

    def test_ranges(self):
        config = SimulatorConfig()
        for seed in range(50):
            g = draw_grasp(15.0, gripper=seed % 2, seed=seed, config=config)
            assert 0 < g.hold_force_n * (1 + config.vibration_fraction) <= config.max_force_n + 1e-9
            assert config.lag_ms[0] <= g.lag_ms <= config.lag_ms[1]
            assert config.angle_deg[0] <= g.angle_deg <= config.angle_deg[1]
            assert 0 <= g.grasp_start_ms <= config.timing_jitter_ms
            assert abs(g.center_yx[0] - CENTER_Y) <= config.center_jitter_px

    def test_switched_off_effects_are_neutral(self):
        g = draw_grasp(12.0, gripper=1, seed=3, config=CLEAN.replace(lag=False))
        assert g.lag_ms == 0 and g.angle_deg == 0 and g.vibration_hz == 0
        assert g.center_yx == (CENTER_Y, (240 - 1) / 2)
        assert g.hold_force_n == CLEAN.gripper_force_n[1]

    @pytest.mark.parametrize("kwargs", [dict(diameter_mm=0.0), dict(gripper=2), dict(seed=-1)])
    def test_bad_arguments_raise(self, kwargs):
        args = dict(diameter_mm=12.0, gripper=0, seed=0) | kwargs
        with pytest.raises(ValueError):
            draw_grasp(args.pop("diameter_mm"), **args)


class TestForce:
    def test_phases(self):
        config = SimulatorConfig()
        recording = simulate_grasp(15.0, gripper=1, seed=2, config=config.replace(contact=False))
        force, hold = recording.force, recording.grasp.hold_force_n
        assert force.shape == (36,) and force.dtype == np.float32
        assert recording.force_t_us.tolist() == [5_000 + 10_000 * i for i in range(36)]
        assert force[0] < 0.25 * hold and force[-1] < 0.25 * hold  # ramps ≈ 5 frames
        hold_phase = force[6:30]
        assert np.all(np.abs(hold_phase - hold) <= config.vibration_fraction * hold + 1e-4)
        assert hold_phase.std() > 0  # vibration
        assert force.max() <= config.max_force_n

    def test_gripper_settings_differ(self):
        holds = [
            [draw_grasp(12.0, gripper=g, seed=s).hold_force_n for s in range(20)] for g in (0, 1)
        ]
        assert np.mean(holds[1]) > np.mean(holds[0]) + 5
        assert np.std(holds[0]) > 0  # experiment-to-experiment variation

    def test_membrane_lag_delays_a_ramp_by_tau(self):
        times = np.arange(0, 400.0, 0.5)
        ramp = np.clip(times - 10.0, 0, None)[None, :]
        for tau in (2.0, 10.0, 30.0):
            lagged = membrane_force(ramp, np.array([tau]), 0.5)
            late = times > 10 + 8 * tau
            np.testing.assert_allclose((ramp - lagged)[0, late], tau, rtol=1e-3)
        np.testing.assert_array_equal(membrane_force(ramp, np.array([0.0]), 0.5), ramp)


class TestContactWidth:
    def test_formula(self):
        config = SimulatorConfig()
        assert contact_half_width(25.0, 18.0, config) == pytest.approx(12.0)
        assert contact_half_width(10.0, 18.0) / contact_half_width(10.0, 12.0) == pytest.approx(
            np.sqrt(1.5)
        )
        cube = config.replace(width_exponent=1 / 3)
        assert contact_half_width(5.0, 18.0, cube) / contact_half_width(5.0, 12.0, cube) == (
            pytest.approx(1.5 ** (1 / 3))
        )

    @pytest.mark.parametrize("exponent", [0.5, 1 / 3])
    def test_measured_width_grows_with_diameter(self, exponent):
        config = CLEAN.replace(width_exponent=exponent, reference_half_width_px=24.0)
        small = simulate_grasp(12.0, gripper=1, seed=0, config=config)
        large = simulate_grasp(18.0, gripper=1, seed=0, config=config)
        ratio = half_width(large.events, config) / half_width(small.events, config)
        assert ratio == pytest.approx(1.5**exponent, rel=0.03)

    def test_measured_width_grows_with_force(self):
        config = CLEAN.replace(reference_half_width_px=24.0)
        weak = simulate_grasp(12.0, gripper=0, seed=0, config=config)
        strong = simulate_grasp(12.0, gripper=1, seed=0, config=config)
        forces = config.gripper_force_n
        ratio = half_width(strong.events, config) / half_width(weak.events, config)
        assert ratio == pytest.approx((forces[1] / forces[0]) ** 0.5, rel=0.03)


class TestPhases:
    def test_most_events_in_grasp_and_release(self):
        recording = simulate_grasp(12.0, seed=0, config=CLEAN.replace(vibration=True))
        t = recording.events["t"]
        phases = (t < 80_000) | (t >= 280_000)  # first and last 8 frames
        assert phases.mean() > 0.9

    def test_grasp_darkens_release_brightens(self):
        events = simulate_grasp(18.0, seed=1, config=CLEAN).events
        grasp, release = events["t"] < 150_000, events["t"] >= 250_000
        assert (events["p"][grasp] == 0).mean() > 0.99  # OFF while the strip widens
        assert (events["p"][release] == 1).mean() > 0.99  # ON while it narrows

    def test_grasp_frames_stand_out_of_default_noise(self):
        recording = simulate_grasp(12.0, gripper=1, seed=4)
        per_frame = recording.frames(crop=recording.contact_crop(), pool=2).sum(dim=(1, 2, 3))
        hold = per_frame[10:26].mean()
        assert per_frame[1:4].min() > 2 * hold and per_frame[-3:].min() > 2 * hold


class TestLag:
    def test_event_activity_lags_force_by_tau(self):
        # With b linear in the force, event activity is proportional to dF_m/dt, so the
        # centroid of the grasp-phase events moves by exactly the membrane's mean delay τ.
        config = CLEAN.replace(width_exponent=1.0, reference_half_width_px=20.0)

        def grasp_centroid_ms(c):
            t = simulate_grasp(18.0, gripper=1, seed=0, config=c).events["t"]
            return t[t < 180_000].mean() / 1000

        instant = grasp_centroid_ms(config.replace(lag=False))
        for tau in (3.0, 10.0, 20.0):
            delay = grasp_centroid_ms(config.replace(lag_ms=(tau, tau))) - instant
            assert delay == pytest.approx(tau, rel=0.15)


class TestStaticScene:
    def test_event_rate_matches_configured_rate(self):
        rate_hz, duration_s = 2.0, 1.0
        config = SimulatorConfig(shot_noise_hz=(rate_hz, rate_hz), hot_pixels=False)
        events = simulate_static(1000 * duration_s, seed=1, config=config)
        expected = rate_hz * 180 * 240 * duration_s
        assert abs(len(events) - expected) < 4 * np.sqrt(expected)  # Poisson sampling error
        on = (events["p"] == 1).sum()
        assert abs(on - len(events) / 2) < 4 * np.sqrt(len(events) / 4)

    def test_log_uniform_rates_average(self):
        low, high = SimulatorConfig().shot_noise_hz
        events = simulate_static(500.0, seed=2, config=SimulatorConfig(hot_pixels=False))
        mean_rate = len(events) / (180 * 240 * 0.5)
        assert mean_rate == pytest.approx((high - low) / np.log(high / low), rel=0.03)

    def test_hot_pixels_fire_often_at_fixed_places(self):
        config = SimulatorConfig(shot_noise=False)
        a, b = simulate_static(200.0, seed=0, config=config), simulate_static(200.0, seed=1, config=config)
        hot_a = set(zip(a["x"].tolist(), a["y"].tolist()))
        assert hot_a == set(zip(b["x"].tolist(), b["y"].tolist()))  # a camera property
        # each pixel is hot with probability hot_pixel_fraction (the library's camera): 4.3 expected here
        hot = np.flatnonzero(simulation._sensor(config)[2][0].numpy())
        assert hot_a == {(int(i % 240), int(i // 240)) for i in hot} and 1 <= len(hot_a) <= 10
        assert len(a) / len(hot_a) >= config.hot_pixel_hz[0] * 0.2 * 0.5

    def test_static_scene_has_no_contact_events(self):
        events = simulate_static(360.0, seed=0, config=SimulatorConfig(shot_noise=False, hot_pixels=False))
        assert len(events) == 0


class TestEvents:
    def test_format(self):
        recording = simulate_grasp(15.0, seed=0)
        events = recording.events
        assert events.dtype == EVENT_DTYPE
        assert np.all(np.diff(events["t"]) >= 0)
        assert events["t"].min() >= 0 and events["t"].max() < 360_000
        assert events["x"].min() >= 0 and events["x"].max() < 240
        assert events["y"].min() >= 0 and events["y"].max() < 180
        assert set(np.unique(events["p"]).tolist()) <= {0, 1}

    def test_crop_holds_every_contact_event(self):
        config = CLEAN.replace(orientation=True, center_jitter_px=6.0)
        recording = simulate_grasp(18.0, gripper=1, seed=3, config=config)
        frames = recording.frames(crop=recording.contact_crop(), pool=2)
        assert frames.shape == (36, 2, 70, 75)
        assert frames.sum().item() == len(recording.events)

    @pytest.mark.parametrize("refractory_us", [200.0, 2500.0])
    def test_refractory_period(self, refractory_us):
        config = CLEAN.replace(refractory_us=refractory_us, vibration=True)
        events = simulate_grasp(18.0, gripper=1, seed=0, config=config).events
        order = np.lexsort((events["t"], events["y"], events["x"]))
        e = events[order]
        same = (np.diff(e["x"]) == 0) & (np.diff(e["y"]) == 0)
        gaps = np.diff(e["t"])[same]
        assert gaps.min() >= refractory_us - 1  # timestamps are floored to whole µs

    def test_longer_refractory_loses_events(self):
        counts = [
            len(simulate_grasp(18.0, seed=0, config=CLEAN.replace(refractory_us=r)).events)
            for r in (0.0, 5000.0)
        ]
        assert counts[1] < counts[0]

    def test_no_mismatch_gives_equal_counts_per_swept_pixel(self):
        config = CLEAN.replace(threshold_mismatch=0.0, refractory_us=0.0)
        events = simulate_grasp(18.0, gripper=1, seed=0, config=config).events
        inner = (np.abs(events["y"] - CENTER_Y) < 4) & (np.abs(events["x"] - 119.5) < 30)
        pixels = events[inner]["x"].astype(np.int64) * 180 + events[inner]["y"]
        counts = np.unique(np.bincount(pixels)[np.unique(pixels)])
        assert len(counts) == 1  # fully swept pixels fire alike: grasp + release

    def test_mismatch_spreads_counts(self):
        events = simulate_grasp(18.0, gripper=1, seed=0, config=CLEAN.replace(threshold_mismatch=0.2)).events
        inner = (np.abs(events["y"] - CENTER_Y) < 4) & (np.abs(events["x"] - 119.5) < 30)
        pixels = events[inner]["x"].astype(np.int64) * 180 + events[inner]["y"]
        assert len(np.unique(np.bincount(pixels)[np.unique(pixels)])) > 1


class TestReproducibility:
    def test_same_seed_same_events(self):
        a, b = simulate_grasp(12.0, seed=7), simulate_grasp(12.0, seed=7)
        np.testing.assert_array_equal(a.events, b.events)
        np.testing.assert_array_equal(a.force, b.force)
        assert not np.array_equal(simulate_grasp(12.0, seed=8).events, a.events)

    def test_batched_equals_one_by_one(self):
        config = SimulatorConfig()
        grasps = [draw_grasp(d, gripper=s % 2, seed=s, config=config) for s, d in enumerate((12.0, 15.0, 18.0))]
        together = simulate_grasps(grasps, config)
        for grasp, recording in zip(grasps, together):
            np.testing.assert_array_equal(simulate_grasps([grasp], config)[0].events, recording.events)

    def test_pinned_output(self):
        # Guards "same seed, same events on any machine": these numbers must not drift.
        events = simulate_grasp(15.0, gripper=1, seed=0).events
        summary = (len(events), int(events["t"].sum() % 1_000_003), int(events["x"].sum()), int(events["p"].sum()))
        assert summary == PINNED

    def test_switching_noise_off_keeps_the_contact_events(self):
        noisy = simulate_grasp(12.0, seed=3, config=SimulatorConfig())
        contact = simulate_grasp(12.0, seed=3, config=SimulatorConfig(shot_noise=False, hot_pixels=False))
        noise = simulate_grasp(12.0, seed=3, config=SimulatorConfig(contact=False))
        merged = np.sort(np.concatenate([contact.events, noise.events]), order=["t", "x", "y", "p"])
        np.testing.assert_array_equal(np.sort(noisy.events, order=["t", "x", "y", "p"]), merged)


class TestEffectsOffAreNotComputed:
    def _forbid(self, monkeypatch, name, module=simulation):
        def fail(*args, **kwargs):
            raise AssertionError(f"{name} ran although its effect is off")

        monkeypatch.setattr(module, name, fail)

    def test_no_contact(self, monkeypatch):
        self._forbid(monkeypatch, "_contact_events")
        self._forbid(monkeypatch, "membrane_force")
        simulate_grasp(12.0, seed=0, config=SimulatorConfig(contact=False))

    def test_no_lag(self, monkeypatch):
        self._forbid(monkeypatch, "membrane_force")
        simulate_grasp(12.0, seed=0, config=CLEAN.replace(lag=False))

    def test_no_noise(self, monkeypatch):
        self._forbid(monkeypatch, "noise_events")
        simulate_grasp(12.0, seed=0, config=CLEAN)


class TestResizeMatchesAnotherBolt:
    """Resizing a 12 mm grasp towards 15 mm, measured on the simulator's frames."""

    def _widths(self, config, beta):
        """Half-widths (resized 12 mm, 15 mm, 12 mm) by the estimator of ``half_width``."""
        config = config.replace(reference_half_width_px=24.0)
        small = simulate_grasp(12.0, gripper=1, seed=0, config=config).frames()
        medium = simulate_grasp(15.0, gripper=1, seed=0, config=config).frames()
        edge = config.edge_px / 2
        return (
            2 * frames_half_width(resize(small, beta)) + beta * edge,
            2 * frames_half_width(medium) + edge,
            2 * frames_half_width(small) + edge,
        )

    def test_linear_contact_paper_beta(self):
        # If the contact image scales with the bolt (exponent 1), the paper's β = 15/12 fits.
        resized, medium, small = self._widths(CLEAN.replace(width_exponent=1.0), 15 / 12)
        assert resized == pytest.approx(medium, rel=0.04)
        assert abs(resized - medium) < abs(small - medium) / 3

    def test_hertz_contact_needs_square_root_beta(self):
        # Under Hertz line contact (exponent 1/2) width grows as sqrt(D): β = (15/12)**0.5 fits,
        # while the paper's β = 1.25 overshoots by about sqrt(1.25).
        resized, medium, small = self._widths(CLEAN, (15 / 12) ** 0.5)
        assert resized == pytest.approx(medium, rel=0.03)
        overshoot, medium, _ = self._widths(CLEAN, 15 / 12)
        assert overshoot / medium == pytest.approx((15 / 12) ** 0.5, rel=0.04)


PINNED = (42883, 60298, 5173491, 19152)  # SIMULATOR_VERSION 3 (the library's pixel model, no refractory period); 2: (42579, 174948, 5118963, 19002)


class TestLagEffects:
    """Issue 18's lag effects: a slower membrane release, a low-passed label."""

    def test_release_time_constant(self):
        from event_transforms.tactile.simulation import membrane_force

        force = np.concatenate([np.zeros(5), np.full(200, 10.0), np.zeros(400)])[None]
        symmetric = membrane_force(force, np.array([5.0]), 0.1)
        slow = membrane_force(force, np.array([5.0]), 0.1, release_ratio=3.0)
        assert np.array_equal(symmetric[:, :205], slow[:, :205])  # pressing: τ
        # relaxing once the force is 0: e^(-t/15 ms) instead of e^(-t/5 ms)
        assert slow[0, 205 + 150] == pytest.approx(slow[0, 205] * math.exp(-15.0 / 15.0), rel=1e-6)
        assert symmetric[0, 205 + 150] == pytest.approx(symmetric[0, 205] * math.exp(-15.0 / 5.0), rel=1e-6)

    def test_defaults_keep_old_output_and_bad_values_raise(self):
        config = SimulatorConfig(sensor_size=(40, 50), n_frames=6)
        same = config.replace(release_lag_ratio=1.0, label_lowpass_ms=0.0)
        a, b = simulate_grasp(15.0, seed=2, config=config), simulate_grasp(15.0, seed=2, config=same)
        assert np.array_equal(a.events, b.events) and np.array_equal(a.force, b.force)
        with pytest.raises(ValueError, match="release_lag_ratio"):
            SimulatorConfig(release_lag_ratio=0.0)
        with pytest.raises(ValueError, match="label_lowpass_ms"):
            SimulatorConfig(label_lowpass_ms=-1.0)


class TestSizeModels:
    """Issue 24: documented variants of how the strip changes with the bolt diameter."""

    def test_defaults_leave_the_output_unchanged(self):
        from event_transforms.tactile.simulation import SIZE_MODELS

        config = SimulatorConfig(shot_noise=False, hot_pixels=False)
        a = simulate_grasp(12.0, seed=3, config=config)
        b = simulate_grasp(12.0, seed=3, config=config.replace(**SIZE_MODELS["hertz"]))
        assert np.array_equal(a.events, b.events)

    def test_growing_strip_is_longer_and_darker_for_a_bigger_bolt(self):
        config = SimulatorConfig(shot_noise=False, hot_pixels=False, orientation=False, center_jitter_px=0.0,
                                 strip_length_exponent=0.5, contrast_exponent=0.5)
        plain = config.replace(strip_length_exponent=0.0, contrast_exponent=0.0)
        for diameter in (12.0, 18.0):
            grown, fixed = (simulate_grasp(diameter, seed=1, config=c) for c in (config, plain))
            extent = lambda r: np.ptp(r.events["x"])  # noqa: E731 - the strip is horizontal
            if diameter == 18.0:  # the reference diameter: unchanged
                assert np.array_equal(grown.events, fixed.events)
            else:
                assert extent(grown) < extent(fixed) and len(grown.events) < len(fixed.events)

    def test_bad_exponent(self):
        with pytest.raises(ValueError, match="strip_length_exponent"):
            SimulatorConfig(strip_length_exponent=float("nan"))


class TestLibraryPixelModel:
    """The contact events are the library's pixel model (``functional.threshold_crossings``)."""

    def test_one_pixel_under_a_ramp_gives_floor_of_the_change_over_the_threshold_at_interpolated_times(self):
        config = CLEAN.replace(threshold_mismatch=0.0, refractory_us=0.0, sensor_size=(3, 3), strip_half_length_px=3.0)
        grasp = draw_grasp(12.0, seed=0, config=config)  # centred at (1, 1), horizontal
        steps = 41
        width_px = np.linspace(0.0, 2.0 + config.edge_px, steps)[None, :]  # the strip's edge sweeps the centre
        (pixel, t_us, p), = simulation._contact_events([grasp], width_px, config)[0]
        centre = pixel == 4
        # the centre pixel's level, log1p(-contrast · cover), rounded to 2**-20 as the simulator does
        cover = np.clip((width_px[0] - 0.0) / config.edge_px, 0.0, 1.0)
        level = np.round(np.log1p(-config.contrast * cover) * 2**20) / 2**20
        drop = -float(level[-1])
        assert int(centre.sum()) == math.floor(drop / config.threshold) == 4  # log(0.4) = -0.92: 4 OFF events
        assert (p[centre] == 0).all()
        # each event at the time the linearly interpolated level crosses its reference
        for j, t in enumerate(np.sort(t_us[centre]), start=1):
            k = int(np.searchsorted(level <= -j * config.threshold, True))  # first substep at or below
            crossing = (k - 1 + (level[k - 1] + j * config.threshold) / (level[k - 1] - level[k])) * 1000.0
            assert (k - 1) * 1000 <= t <= k * 1000 and abs(t - crossing) <= 1.0

    def test_contact_events_are_the_core_on_the_active_pixels(self):
        from event_transforms.functional import threshold_crossings

        config = CLEAN.replace(sensor_size=(30, 40), strip_half_length_px=8.0, reference_half_width_px=4.0)
        grasp = draw_grasp(15.0, seed=2, config=config)
        steps = int(config.duration_ms / config.substep_ms) + 1
        width_px = 5.0 * np.sin(np.linspace(0.0, np.pi, steps))[None, :] ** 2
        (pixel, t_us, p), = simulation._contact_events([grasp], width_px, config)[0]
        ys, xs = np.divmod(np.arange(30 * 40), 40)
        u, v = np.abs(ys - grasp.center_yx[0]), np.abs(xs - grasp.center_yx[1])
        active = np.flatnonzero((u < width_px.max()) & (v < 8.0))
        cover = np.clip(width_px[0][:, None] / config.edge_px - u[active] / config.edge_px, 0.0, 1.0)
        depth = config.contrast * np.clip((8.0 - v[active]) / config.edge_px, 0, 1)
        level = torch.from_numpy(np.round(np.log1p(-depth * cover) * 2**20) / 2**20).float()
        on, off, _ = simulation._sensor(config)
        (_, column, t, q), _ = threshold_crossings(level, torch.arange(steps, dtype=torch.float64) * 1000.0,
                                                   on[0, active], off[0, active], refractory_us=config.refractory_us)
        expected = sorted(zip(active[column.numpy()].tolist(), torch.floor(t).long().tolist(), q.tolist()))
        assert len(expected) > 100 and sorted(zip(pixel.tolist(), t_us.tolist(), p.tolist())) == expected
