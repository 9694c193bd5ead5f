"""Tests for ``event_transforms.viz``."""

from __future__ import annotations

import pytest
import torch
import numpy as np
from PIL import Image
import event_transforms as et

from event_transforms.viz import (
    BACKGROUND,
    OFF_COLOR,
    ON_COLOR,
    compare_transform,
    frames_to_rgb,
    make_event_grid,
    save_event_grid,
)


def sample(batch: int | None = None, t: int = 3, h: int = 17, w: int = 11) -> torch.Tensor:
    shape = (t, 2, h, w) if batch is None else (batch, t, 2, h, w)
    return torch.poisson(torch.full(shape, 0.3), generator=torch.Generator().manual_seed(0))


class TestFramesToRgb:
    def test_colours(self):
        frames = torch.zeros(1, 2, 1, 4)
        frames[0, 1, 0, 0] = 5  # ON only
        frames[0, 0, 0, 1] = 5  # OFF only
        frames[0, :, 0, 2] = 5  # both
        rgb = frames_to_rgb(frames)[0, :, 0].T.tolist()
        assert rgb[0] == list(ON_COLOR) and rgb[1] == list(OFF_COLOR) and rgb[3] == list(BACKGROUND)
        assert rgb[2] != rgb[0] and rgb[2] != rgb[1]

    @pytest.mark.parametrize("dtype", [torch.uint8, torch.int64, torch.float16, torch.float64])
    def test_shapes_and_dtypes(self, dtype):
        frames = sample(batch=2).to(dtype)
        rgb = frames_to_rgb(frames)
        assert rgb.shape == (2, 3, 3, 17, 11) and rgb.dtype == torch.uint8
        assert frames_to_rgb(frames[0]).shape == (3, 3, 17, 11)

    def test_per_sequence_scale_and_fixed_vmax(self):
        frames = torch.zeros(2, 1, 2, 1, 1)
        frames[0, 0, 1] = 1
        frames[1, 0, 1] = 10
        auto = frames_to_rgb(frames)
        assert torch.equal(auto[0], auto[1])  # each sequence scaled to its own maximum
        fixed = frames_to_rgb(frames, vmax=10.0, gamma=1.0)
        assert not torch.equal(fixed[0], fixed[1])

    def test_empty_and_input_unchanged(self):
        frames = torch.zeros(2, 2, 3, 3)
        version = frames._version
        rgb = frames_to_rgb(frames)
        assert bool((rgb == torch.tensor(BACKGROUND, dtype=torch.uint8).view(3, 1, 1)).all())
        assert frames._version == version and frames.sum() == 0

    def test_bad_input_raises(self):
        with pytest.raises(ValueError, match="expected"):
            frames_to_rgb(torch.zeros(3, 3, 4, 4))
        with pytest.raises(ValueError, match="on_color"):
            frames_to_rgb(torch.zeros(1, 2, 4, 4), on_color=(0, 0, 300))
        with pytest.raises(ValueError, match="gamma"):
            frames_to_rgb(torch.zeros(1, 2, 4, 4), gamma=0)


class TestGrid:
    def test_sequence_and_batch_layout(self):
        one = make_event_grid(sample(t=5), nrow=5, padding=1)
        assert one.shape == (3, 17 + 2, 5 * 12 + 1)
        batch = make_event_grid(sample(batch=2, t=4), padding=0, upscale=2)
        assert batch.shape == (3, 2 * 34, 4 * 22)  # one row per sequence

    def test_png_round_trip(self, tmp_path):
        frames = sample(t=4)
        path = save_event_grid(frames, tmp_path / "sub" / "grid.png", padding=0)
        image = torch.from_numpy(np.array(Image.open(path))).permute(2, 0, 1)
        assert torch.equal(image, make_event_grid(frames, padding=0))


class TestCompareTransform:
    def test_rows_before_and_after(self, tmp_path):
        frames = sample(t=4)

        def zero(x, *, generator=None):
            return torch.zeros_like(x)

        grid = compare_transform(frames, zero, tmp_path / "cmp.png", padding=0)
        assert grid.shape == (3, 2 * 17, 4 * 11)
        assert torch.equal(grid[:, :17], make_event_grid(frames, nrow=4, padding=0))
        assert bool((grid[:, 17:] == 255).all())  # the "after" row is empty: background
        assert (tmp_path / "cmp.png").exists()

    def test_batch_and_metadata(self):
        import event_transforms as et

        resize = et.ResizeToTarget(15.0, center="image")  # reads each sample's size from metadata
        frames = sample(batch=3, t=2)
        grid = compare_transform(frames, resize, metadata={"diameter_mm": 12.0}, padding=0)
        assert grid.shape == (3, 6 * 17, 2 * 11)
        expected = compare_transform(frames, lambda x: et.Resize(1.25, center="image")(x), padding=0)
        assert torch.equal(grid, expected)
        with pytest.raises(ValueError, match="diameter_mm"):
            compare_transform(frames, resize)

    def test_shape_change_raises(self):
        with pytest.raises(ValueError, match="shape"):
            compare_transform(sample(t=2), lambda x: x[:, :1])


class TestLabelledFigures:
    """Issue 18: rows named before/after, polarity legend, frame times; scenes with their gaps."""

    def test_acting_frames(self):
        from event_transforms.viz import acting_frames

        before = torch.zeros(10, 2, 4, 5)
        after = et.FrameShift(-1)(before.clone())
        assert acting_frames(before, after, 4).tolist() == [0, 3, 6, 9]  # identity: evenly spaced
        before[6, 0, 1, 1] = 3.0
        after = et.FrameShift(-1)(before)
        assert acting_frames(before, after, 2).tolist() == [5, 6]
        with pytest.raises(ValueError, match="one sequence"):
            acting_frames(before.unsqueeze(0), after.unsqueeze(0))

    def test_plot_transform_and_scene(self, tmp_path):
        pytest.importorskip("matplotlib")
        from event_transforms.viz import plot_scene, plot_transform

        g = torch.Generator().manual_seed(0)
        frames = torch.poisson(torch.full((6, 12, 2, 16, 20), 0.05), generator=g)
        frames[:, 3:8, 0, 7:9, 3:17] += 3.0
        path = plot_transform(frames[0], et.FrameShift(-2)(frames[0]), tmp_path / "t.png", title="fs-2")
        fig = plot_transform(frames[0], et.FrameShift(-2)(frames[0]), title="fs-2")
        labels = [t.get_text() for t in fig.axes[0].get_yticklabels()]
        assert labels == ["before", "after"] and "ms" in fig.axes[0].get_xticklabels()[0].get_text()
        assert (tmp_path / "t.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path is not None
        fig = plot_scene(frames[:3], frames[3:], tmp_path / "s.png", title="x", gaps=("timing",), every=3)
        text = fig.texts[0].get_text() if fig.texts else fig._suptitle.get_text()
        assert "gaps: timing" in text
        rows = [t.get_text() for t in fig.axes[0].get_yticklabels()]
        assert rows == ["training 1", "training 2", "deployment 1", "deployment 2"]
        assert (tmp_path / "s.png").exists()
