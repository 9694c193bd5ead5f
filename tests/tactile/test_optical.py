"""The optical generator and the camera it shares with the built-in one (taxim tests skip without the extra)."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import warnings

import numpy as np
import pytest
import torch

from event_transforms.tactile import datasets
from event_transforms.tactile.generators import optical
from event_transforms.tactile.generators.optical import (
    OpticalConfig,
    OpticalObject,
    height_map,
    membrane_depth,
    press_depth,
    render_table,
    simulate_optical,
)
from event_transforms.tactile.benchmark_scenes import (
    BASE_SESSION,
    OPTICAL_SCENES,
    SCENES,
    BenchmarkScene,
    Session,
    get_scene,
)
from event_transforms.tactile.simulation import SimulatorConfig, draw_grasp, force_profile

class TestOneCamera:
    def test_builtin_camera_is_the_library_one(self):
        """The built-in simulator's camera is ``camera_pixels`` of its ``sensor_seed`` (the optical
        generator's thresholds come from ``emulate_events``, the same draws)."""
        from event_transforms.functional import camera_pixels
        from event_transforms.tactile import simulation

        config = SimulatorConfig(sensor_size=(20, 30), sensor_seed=4)
        on, off, rate = simulation._sensor(config)
        expected = camera_pixels(600, camera_seed=4, threshold_on=0.2, mismatch=0.03, noise_hz=1.0,
                                 hot_pixel_fraction=1e-4, hot_pixel_hz=100.0, noise_spread=10.0, hot_pixel_spread=2.0)
        assert all(torch.equal(a, b) for a, b in zip((on, off, rate), expected))
        assert simulation._sensor(config) is simulation._sensor(config)  # cached


class TestContactAndMembrane:
    @pytest.mark.parametrize("diameter", [12.0, 15.0, 18.0])
    def test_cylinder_depth_inverts_the_winkler_line_contact(self, diameter):
        config = OpticalConfig()
        force = np.array([0.0, 1.0, 7.5, 25.0])
        depth = press_depth(force, OpticalObject("cylinder", diameter), config)
        k, length, radius = config.foundation_n_per_mm3, config.contact_length_mm, diameter / 2
        # F = ∫ k (δ − x²/2R) dx · L over |x| < √(2Rδ), integrated numerically
        for f, d in zip(force, depth):
            half = math.sqrt(2 * radius * d)
            x = np.linspace(-half, half, 20_001)
            carried = k * length * np.trapezoid(d - x**2 / (2 * radius), x)
            assert carried == pytest.approx(f, rel=1e-6, abs=1e-9)

    def test_a_larger_cylinder_presses_less_deep(self):
        depths = [float(press_depth(20.0, OpticalObject("cylinder", d))) for d in (12.0, 15.0, 18.0)]
        assert depths[0] > depths[1] > depths[2]

    def test_hex_face_is_a_flat_punch(self):
        config = OpticalConfig()
        depth = float(press_depth(10.0, OpticalObject("hex", 10.0), config))
        assert depth * config.foundation_n_per_mm3 * math.sqrt(3) / 2 * 100.0 == pytest.approx(10.0)

    @pytest.mark.parametrize("bad", [-1.0, float("nan")])
    def test_bad_force_is_refused(self, bad):
        with pytest.raises(ValueError, match="force_n"):
            press_depth(np.array([1.0, bad]), OpticalObject("cylinder", 15.0))

    @pytest.mark.parametrize("r", [0.25, 0.5, 1.0])
    def test_sls_creep_after_a_ramp_and_hold_matches_the_formula(self, r):
        tau, slope, t_ramp = 8.0, 0.01, 20
        t = np.arange(121, dtype=np.float64)
        elastic = slope * np.minimum(t, t_ramp)
        out = membrane_depth(elastic[None], np.array([tau]), 1.0, instant_fraction=r)[0]
        # lag of a ramp: a(t − τ(1 − e^(−t/τ))); after the ramp it creeps to a·t_ramp
        lag_at_ramp_end = slope * (t_ramp - tau * (1 - math.exp(-t_ramp / tau)))
        held = t[t_ramp:] - t_ramp
        lagged = slope * t_ramp + (lag_at_ramp_end - slope * t_ramp) * np.exp(-held / tau)
        expected = r * elastic[t_ramp:] + (1 - r) * lagged
        np.testing.assert_allclose(out[t_ramp:], expected, rtol=0, atol=1e-12)
        np.testing.assert_allclose(out[:t_ramp + 1], r * elastic[:t_ramp + 1] + (1 - r) * slope * (
            t[:t_ramp + 1] - tau * (1 - np.exp(-t[:t_ramp + 1] / tau))), atol=1e-12)

    def test_slower_release_lags_more_on_the_way_down(self):
        up_down = np.concatenate([np.linspace(0, 0.5, 30), np.linspace(0.5, 0.0, 30)])[None]
        fast = membrane_depth(up_down, np.array([5.0]), 1.0, instant_fraction=0.5)
        slow = membrane_depth(up_down, np.array([5.0]), 1.0, instant_fraction=0.5, release_ratio=3.0)
        np.testing.assert_array_equal(fast[0, :30], slow[0, :30])
        assert (slow[0, 35:] > fast[0, 35:]).all()

    def test_config_checks_name_the_setting(self):
        with pytest.raises(ValueError, match="instant_fraction"):
            OpticalConfig(instant_fraction=0.0)
        with pytest.raises(ValueError, match="render_scale"):
            OpticalConfig(render_scale=0)
        with pytest.raises(ValueError, match="kind"):
            OpticalObject("sphere", 10.0)
        with pytest.raises(ValueError, match="channel"):
            OpticalConfig(channel="blue")
        with pytest.raises(TypeError, match="shadows must be a bool, got 1"):
            OpticalConfig(shadows=1)  # type: ignore[arg-type]

    def test_shadows_key_the_table_and_reach_the_renderer(self, tmp_path):
        seen = []

        def fake(maps):
            seen.append(maps.shape[0])
            return np.repeat(np.clip(0.5 + maps, 0, 1)[..., None], 3, axis=-1)

        small = dict(render_scale=8, depth_step_mm=0.4, max_depth_mm=0.8)
        cylinder = OpticalObject("cylinder", 15.0)
        render_table(cylinder, 0.0, (30, 40), OpticalConfig(**small), root=tmp_path, renderer=fake)
        optical._MEMORY.tables.clear()
        render_table(cylinder, 0.0, (30, 40), OpticalConfig(**small, shadows=False), root=tmp_path, renderer=fake)
        assert len(seen) == 2 and len(list(tmp_path.glob("optical-table-v*.npz"))) == 2  # another key: rendered again
        assert OpticalConfig().shadows  # on since version 3 (benchmarks/tactile/recorded_vs_generators.py)
        # the key without shadows is the one tables had before the option existed
        key = optical._table_key(cylinder, 0.0, OpticalConfig(shadows=False), (30, 40), "h")
        assert "shadows" not in key and '"shadows": true' in optical._table_key(cylinder, 0.0, OpticalConfig(), (30, 40), "h")

    def test_the_luminance_rule_picks_the_channel(self):
        from event_transforms.tactile.generators.optical import _luminance

        rgb = np.zeros((1, 4, 4, 3))
        rgb[..., 0], rgb[..., 1], rgb[..., 2] = 0.2, 0.5, 0.9
        assert float(_luminance(rgb, (2, 2), 0)[0, 0, 0]) == pytest.approx(0.2)
        assert float(_luminance(rgb, (2, 2), 2)[0, 0, 0]) == pytest.approx(0.9)
        assert float(_luminance(rgb, (2, 2), "luma")[0, 0, 0]) == pytest.approx(0.299 * 0.2 + 0.587 * 0.5 + 0.114 * 0.9)
        assert OpticalConfig().channel == 0  # red: the recorded sensor's closest (benchmarks/tactile/recorded_vs_generators.py)


class TestHeightMaps:
    def test_rotating_the_object_rotates_its_height_map(self):
        config = OpticalConfig(render_scale=8)
        for obj in (OpticalObject("cylinder", 15.0), OpticalObject("hex", 8.0)):
            turned = height_map(obj, 180.0, config)
            np.testing.assert_allclose(turned, np.rot90(height_map(obj, 0.0, config), 2), atol=1e-5)
        hex_map = height_map(OpticalObject("hex", 8.0), 0.0, config)
        np.testing.assert_allclose(height_map(OpticalObject("hex", 8.0), 60.0, config), hex_map, atol=1e-5)
        assert float(hex_map.min()) == 0.0


# --------------------------------------------------------------------------- taxim

SMALL = OpticalConfig(render_scale=8, depth_step_mm=0.2, max_depth_mm=0.8)


@pytest.fixture(scope="module")
def taxim_available():
    pytest.importorskip("taxim")
    pytest.importorskip("jax")


@pytest.fixture(autouse=True)
def _fresh_table_memory():
    optical._MEMORY.tables.clear()
    yield
    optical._MEMORY.tables.clear()


@pytest.mark.slow  # taxim compiles its renderer once per grid (seconds)
@pytest.mark.usefixtures("taxim_available")
class TestRenderTables:
    def test_one_simulator_per_grid(self):
        assert optical._taxim("gelsight_mini", 0.236) is optical._taxim("gelsight_mini", 0.236)

    def test_the_renderer_draws_shadows_when_asked(self):
        # at render_scale 8 (0.24 mm/px) taxim's shadows are too short to reach a pixel: 4 here
        grid = OpticalConfig(render_scale=4)
        pressed = height_map(OpticalObject("cylinder", 15.0), 0.0, grid)[None] - 0.4
        with_shadows = optical.taxim_renderer(grid)(pressed)
        without = optical.taxim_renderer(OpticalConfig(render_scale=4, shadows=False))(pressed)
        assert with_shadows.shape == without.shape and float(np.abs(with_shadows - without).max()) > 0.01

    def test_cached_keyed_and_rebuilt_when_corrupt(self, tmp_path, monkeypatch):
        cylinder = OpticalObject("cylinder", 15.0)
        table = render_table(cylinder, 0.0, (30, 40), SMALL, root=tmp_path)
        assert table.shape == (5, 30, 40) and table.dtype == np.float32
        files = sorted(tmp_path.glob("optical-table-v*.npz"))
        assert len(files) == 1
        # pressing changes the light, more the deeper
        change = [float(np.abs(table[k] - table[0]).max()) for k in range(5)]
        assert change[-1] > 0.02 and change[-1] > change[1]

        # from disk, without rendering
        optical._MEMORY.tables.clear()
        monkeypatch.setattr(optical, "taxim_renderer", lambda config=None: pytest.fail("rendered again"))
        np.testing.assert_array_equal(render_table(cylinder, 0.0, (30, 40), SMALL, root=tmp_path), table)
        monkeypatch.undo()

        # keyed: another angle, size or grid is another file
        render_table(cylinder, 10.0, (30, 40), SMALL, root=tmp_path)
        render_table(OpticalObject("cylinder", 12.0), 0.0, (30, 40), SMALL, root=tmp_path)
        assert len(list(tmp_path.glob("optical-table-v*.npz"))) == 3

        # a corrupt file is named in a warning and rebuilt
        optical._MEMORY.tables.clear()
        files[0].write_bytes(b"not a table")
        with pytest.warns(UserWarning, match=str(files[0].name)):
            rebuilt = render_table(cylinder, 0.0, (30, 40), SMALL, root=tmp_path)
        np.testing.assert_array_equal(rebuilt, table)  # the render is reproducible (REPRODUCIBLE_XLA_FLAGS)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            optical._MEMORY.tables.clear()
            render_table(cylinder, 0.0, (30, 40), SMALL, root=tmp_path)

    def test_memory_is_bounded(self, tmp_path):
        tiny = OpticalConfig(render_scale=8, depth_step_mm=0.4, max_depth_mm=0.8, table_memory_mb=3 * 30 * 40 * 4 * 1.5 / 2**20)
        for angle in (0.0, 5.0, 10.0, 15.0):
            render_table(OpticalObject("cylinder", 15.0), angle, (30, 40), tiny, root=tmp_path)
        assert len(optical._MEMORY.tables) == 1

    @pytest.mark.parametrize("obj", [OpticalObject("cylinder", 15.0), OpticalObject("hex", 8.0)])
    def test_a_turned_object_is_not_a_turned_image(self, tmp_path, obj):
        # Turned by 180° the object's height map is exactly the turned map (tested above);
        # under the sensor's fixed, coloured light its image is not the turned image.
        config = OpticalConfig(render_scale=4, depth_step_mm=0.3, max_depth_mm=0.6)
        upright = render_table(obj, 0.0, (60, 80), config, root=tmp_path)
        turned = render_table(obj, 180.0, (60, 80), config, root=tmp_path)
        contact_upright = upright[-1] - upright[0]
        contact_turned = turned[-1] - turned[0]
        distance = np.linalg.norm(contact_turned - np.rot90(contact_upright, 2)) / np.linalg.norm(contact_upright)
        assert distance > 0.2, distance


class TestReproducibleXlaFlags:
    """taxim's render is reproducible only on XLA's single-threaded CPU kernels: set before JAX starts, else named."""

    def test_added_to_the_users_flags_before_jax_starts(self, monkeypatch):
        monkeypatch.setenv("XLA_FLAGS", "--xla_dump_to=/tmp/nowhere")
        monkeypatch.setattr(optical, "_jax_started", lambda: False)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            optical._reproducible_xla()
            optical._reproducible_xla()  # a second call adds nothing
        assert os.environ["XLA_FLAGS"].split() == ["--xla_dump_to=/tmp/nowhere", *optical.REPRODUCIBLE_XLA_FLAGS]

    def test_already_set_is_left_alone(self, monkeypatch):
        monkeypatch.setenv("XLA_FLAGS", " ".join(reversed(optical.REPRODUCIBLE_XLA_FLAGS)))
        monkeypatch.setattr(optical, "_jax_started", lambda: pytest.fail("no need to ask"))
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            optical._reproducible_xla()
        assert os.environ["XLA_FLAGS"] == " ".join(reversed(optical.REPRODUCIBLE_XLA_FLAGS))

    def test_jax_started_without_them_is_named(self, monkeypatch):
        monkeypatch.delenv("XLA_FLAGS", raising=False)
        monkeypatch.setattr(optical, "_jax_started", lambda: True)
        with pytest.warns(optical.RenderNotReproducibleWarning, match="JAX started before"):
            optical._reproducible_xla()
        assert "XLA_FLAGS" not in os.environ  # too late to matter: not touched

    def test_a_users_other_value_is_kept_and_named(self, monkeypatch):
        monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=true")
        monkeypatch.setattr(optical, "_jax_started", lambda: False)
        with pytest.warns(optical.RenderNotReproducibleWarning, match="sets --xla_cpu_multi_thread_eigen=true"):
            optical._reproducible_xla()
        assert os.environ["XLA_FLAGS"] == "--xla_cpu_multi_thread_eigen=true"

    def test_jax_not_imported_has_not_started(self, monkeypatch):
        monkeypatch.delitem(sys.modules, "jax", raising=False)
        assert optical._jax_started() is False

    def test_asked_afresh_every_time_while_taxim_is_built_once(self):
        # whether JAX started can change; taxim's simulator (and its compiled renderer) is kept per grid
        assert not hasattr(optical._jax_started, "cache_info")
        assert optical._taxim.cache_info().maxsize == 2  # type: ignore[attr-defined]


_RENDER_SIX_TIMES = """
import hashlib, os, warnings
import numpy as np
warnings.simplefilter("error", UserWarning)
from event_transforms.tactile.generators import optical
config = optical.OpticalConfig()
pressed = optical.height_map(optical.OpticalObject("cylinder", 15.0), 2.5, config)[None] - config.depths_mm[:, None, None]
render = optical.taxim_renderer(config)
print(os.environ["XLA_FLAGS"])
for _ in range(6):
    print(hashlib.sha256(np.ascontiguousarray(render(pressed)).tobytes()).hexdigest())
"""


@pytest.mark.slow  # six renders of a full 21-map table in a fresh process, the cores kept busy (about 20 s)
@pytest.mark.usefixtures("taxim_available")
def test_a_full_table_renders_the_same_on_every_call():
    # Multi-threaded, XLA's kernels split their work by the threads' timing: on the loaded 2-core
    # machine the same maps gave 3 different images in six calls (benchmarks/tactile/optical_render.py), one in
    # five with two busy processes beside it; on a quiet machine the same image every time. So the
    # cores are kept busy while the table renders.
    env = {key: value for key, value in os.environ.items() if key != "XLA_FLAGS"}
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(os.cpu_count() or 2)]
    try:
        out = subprocess.run([sys.executable, "-c", _RENDER_SIX_TIMES], capture_output=True, text=True, env=env,
                             timeout=600, check=True).stdout.split("\n")
    finally:
        for process in busy:
            process.kill()
            process.wait()
    assert out[0].split() == list(optical.REPRODUCIBLE_XLA_FLAGS)
    hashes = [line for line in out[1:] if line]
    assert len(hashes) == 6 and len(set(hashes)) == 1, hashes


@pytest.mark.usefixtures("taxim_available")
class TestSimulateOptical:
    CONFIG = SimulatorConfig(sensor_size=(30, 40), center_jitter_px=2.0, threshold=0.05, n_frames=12,
                             grasp_ms=30.0, release_ms=30.0)

    def test_recordings_like_the_builtin_generator(self, tmp_path):
        grasps = [draw_grasp(d, seed=s, config=self.CONFIG) for d, s in [(12.0, 0), (18.0, 1)]]
        first = simulate_optical(grasps, self.CONFIG, SMALL, root=tmp_path)
        again = simulate_optical(grasps, self.CONFIG, SMALL, root=tmp_path)
        frame_ms = (np.arange(12) + 0.5) * 10.0
        for recording, repeat, grasp in zip(first, again, grasps):
            events = recording.events
            np.testing.assert_array_equal(events, repeat.events)  # same seed, same events
            assert (np.diff(events["t"]) >= 0).all()
            assert events["x"].max() < 40 and events["y"].max() < 30 and events["t"].max() < 120_000
            np.testing.assert_array_equal(recording.force, force_profile([grasp], frame_ms, self.CONFIG)[0]
                                          .astype(np.float32))
            assert recording.frames().shape == (12, 2, 30, 40)
        static = self.CONFIG.replace(contact=False, shot_noise=False, hot_pixels=False)
        leaky = OpticalConfig(render_scale=8, leak_hz=50.0, random_reference=True)
        quiet = simulate_optical(grasps[:1], static, leaky, root=tmp_path)[0]
        # leak events only: every pixel fires ON every 20 ms, at a random phase
        per_pixel = np.bincount(quiet.events["y"].astype(int) * 40 + quiet.events["x"], minlength=1200)
        assert (quiet.events["p"] == 1).all() and set(per_pixel.tolist()) <= {5, 6}
        assert len(simulate_optical(grasps[:1], static, SMALL, root=tmp_path)[0].events) == 0  # reset: none

    def test_refuses_what_it_does_not_model(self, tmp_path):
        grasp = draw_grasp(15.0, seed=0, config=self.CONFIG)
        with pytest.raises(ValueError, match="label_lowpass_ms"):
            simulate_optical([grasp], self.CONFIG.replace(label_lowpass_ms=5.0), SMALL, root=tmp_path)
        with pytest.raises(ValueError, match="max_depth_mm"):
            simulate_optical([grasp], self.CONFIG, OpticalConfig(render_scale=8, depth_step_mm=0.01,
                                                                  max_depth_mm=0.02), root=tmp_path)


class TestOpticalScenes:
    def test_every_role_is_reachable_and_keeps_its_gaps(self):
        roles = {"optical-control": "control", "optical-paper": "paper", "optical-orientation": "orientation",
                 "optical-paper-membrane": "paper-membrane", "optical-paper-offset": "paper-offset"}
        for name, role in roles.items():
            scene = get_scene(name)
            assert scene is OPTICAL_SCENES[name] and name not in SCENES
            assert scene.train.generator == scene.deploy.generator == "optical"
            assert scene.gaps == SCENES[role].gaps
            assert scene.matched_methods == SCENES[role].matched_methods
        assert get_scene("optical-noise").gaps == ("noise", "sensor")
        assert get_scene("optical-orientation-hex").gaps == ("orientation",)

    def test_generator_is_checked(self):
        with pytest.raises(ValueError, match="generator"):
            Session((15.0,), SimulatorConfig(), "raytraced")
        with pytest.raises(ValueError, match="one generator"):
            BenchmarkScene("mixed", "", BASE_SESSION, BASE_SESSION.replace(generator="optical"))

    def test_the_cache_key_names_the_generator_and_builtin_keys_are_pinned(self):
        seeds = range(0, 48)
        builtin = datasets._cache_name(BASE_SESSION, seeds, (140, 150), 2)
        # SIMULATOR_VERSION 3, no refractory period (version 2's were tactile-grasps-v2-8546bc2ef0553ea7.pt and -6dfbb10742bdecc4.pt)
        assert builtin == "tactile-grasps-v3-aa16a0ef0e944b38.pt"
        membrane = SCENES["paper-membrane"].deploy
        assert datasets._cache_name(membrane, range(10_000, 10_024), (140, 150), 2) == (
            "tactile-grasps-v3-17fcb75ff08f6c69.pt"
        )
        assert datasets._cache_name(BASE_SESSION.replace(generator="optical"), seeds, (140, 150), 2) != builtin

    def test_methods_follow_the_role(self):
        from event_transforms.tactile.methods import methods_for

        assert methods_for("optical-paper") == methods_for("paper")
        assert methods_for("optical-control") == methods_for("control")
        assert methods_for("optical-orientation") == methods_for("orientation")



def test_optical_sessions_simulate_with_the_optical_generator(monkeypatch):
    calls = []

    def fake(grasps, config, *, kind):
        calls.append((len(grasps), config, kind))
        return ["optical"] * len(grasps)

    monkeypatch.setattr(optical, "simulate_optical", fake)
    session = get_scene("optical-control").train
    assert session.simulate(session.grasps(2, seed=0)) == ["optical", "optical"]
    assert calls == [(2, session.config, "cylinder")]
    hex_session = get_scene("optical-orientation-hex").deploy
    hex_session.simulate(hex_session.grasps(1, seed=0))
    assert calls[-1] == (1, hex_session.config, "hex")
    builtin = BASE_SESSION.simulate(BASE_SESSION.grasps(1, seed=0))
    assert len(calls) == 2 and builtin[0].events.dtype.names == ("x", "y", "t", "p")
