"""Infer a scene from a user's own data: labelled training frames and unlabeled deployment frames.

A user of the library rarely knows the numbers a :class:`~event_transforms.Scene` asks for:
how much later the deployment camera's events come, how far the contact turns, how noisy
the new camera is. They do have training recordings and recordings from the deployment
setup without labels (the sensor that gives the labels is what they want to replace). Each physical
factor leaves a trace in the frames that needs no label:

==============  =====================================================  =====================
factor          estimator (per sequence)                               policy built
==============  =====================================================  =====================
orientation     the contact axis: major axis of the contact pixels'   rotation over ± the
                second moments (:func:`~event_transforms.functional.   deployment's largest
                contact_axis`), in degrees                             |angle|
timing          onset latency: when the contact pixels' event count    frame shift by the
                (background removed) first reaches 20 % of its peak,   difference in frames
                interpolated between frame centres, in ms              (TES for < ½ frame)
noise           background rate: events per pixel and frame in the     the deployment's own
                sequence's quietest frames; hot pixels: pixels firing  quiet frames as a
                in every one of those frames                           noise bank
size            contact half-width: twice the contact pixels' median   stretch to the
                distance across the axis (reported); the gap itself    deployment size
                comes from the object sizes the user gives (below)
==============  =====================================================  =====================

Each estimate is a distribution over sequences; the gap test compares training and
deployment means by Welch's z (difference over its standard error) and declares a gap only
where ``|z| > z_gap`` (3: one false gap in about 370 per factor when nothing differs) *and*
the difference is large enough to matter (``min_effect``). The uncertainty of every estimate
is in :attr:`~event_transforms.Scene.evidence`.

**Hot pixels.** A deployment camera with more hot pixels (pixels firing in every quiet
frame) is a noise gap too: the hot-pixel count per sequence is compared in the same way
(``|z| > z_gap`` and at least 1.5× as many and one more per sequence), and either trace
declares the noise gap.

**Detection limits.** A difference smaller than ``z_gap`` standard errors cannot be told
from chance; the standard error shrinks as 1/√N with N recordings per side. Where no gap is
declared, each factor's verdict (``scene.evidence["verdicts"]``) says either "no gap"
(a difference as large as the smallest that matters, ``min_effect``, would have been seen)
or "not resolvable from N unlabeled deployment windows: a difference below L would not be seen",
with L = ``z_gap`` × the standard error. Measured on the package's simulator with 48
training and 24 deployment recordings (the detection-rate benchmark of ``benchmarks/``, its RESULTS.md
"infer_scene detection rate"): under the benchmark's 60 ms start jitter the onset's
standard error is 5–6 ms per side, so a timing gap under about 17 ms (under two 10 ms
frames) is not resolvable — one-frame clock offsets and short lags go undetected —
while a 20 ms delay is found in most blocks; orientation, background-rate and hot-pixel
gaps of the sizes in RESULTS.md are found reliably, and no gap was declared where none
existed.

**Timing measured another way.** An application with more than frames (force labels, say)
can measure the timing gap directly and pass its test as ``timing=``: a mapping with the keys
:func:`difference_test` returns (``train``, ``deploy``, ``difference``, ``se``, ``z``,
``resolvable``, ``gap``), a ``statistic`` and a ``source`` naming what it read, and a
``verdict`` sentence for when it is not resolvable. A resolvable test replaces the onset test,
which stays in ``evidence["timing"]["onset"]``; an unresolvable one is kept under
``evidence["timing"]["alternative"]`` and the onset test decides. An application with
labelled recordings builds it from lags of the events behind their labels.

**A start jitter enters the onset whole.** The onset is when a recording *starts* plus its
lag, so two sessions whose recordings happen to start at different times on average differ in
onset without any delay: on simulated sessions with a 60 ms start jitter
that reads +4.5 ms on every scene without a timing gap, inside the standard error. A timing
test that measures events against labels cancels the start.

**Small samples.** A test with fewer than 2 windows on a side, or whose standard error is 0
(every value alike) with fewer than ``MIN_WINDOWS`` windows on a side, cannot declare
anything: its verdict is "not resolvable" with what would resolve it, never "gap" (a zero
standard error made any difference infinitely significant) nor "no gap". Below ``MIN_WINDOWS`` (8) windows on a side, :func:`infer_scene` warns
(:class:`SmallSampleWarning`): the standard errors are then themselves unreliable.

**Size is not identifiable from unlabeled frames.** Where the contact's width grows with both
the load and the object's size, a larger object hides in the load distribution: the frames
alone cannot tell them apart. The user knows the object sizes; give them as ``train_sizes``
and ``deploy_sizes`` and a size gap is declared from them, stretched by (D₂/D₁)^½. The width
ratio is reported, never used to declare a gap.
"""

from __future__ import annotations

__all__ = ["infer_scene", "sequence_statistics", "difference_test", "FACTOR_TESTS", "MIN_WINDOWS", "SmallSampleWarning"]

import math
from collections.abc import Mapping, Sequence
from typing import Any

import torch
from torch import Tensor

from ._validation import check_frames, describe
from .events.dropped import warn_at_caller
from .functional._warp import axis_radians
from .scenes import Scene

#: The gap test of each frame-based factor: (statistic, smallest difference that matters).
#: ``angle_abs_deg`` is the absolute contact angle; ``onset_ms`` the onset latency;
#: ``log_background`` the log of the background rate (a ratio of 1.5 is ``log(1.5)``).
FACTOR_TESTS: dict[str, tuple[str, float]] = {
    "orientation": ("angle_abs_deg", 5.0),
    "timing": ("onset_ms", 3.0),
    "noise": ("log_background", math.log(1.5)),
}
#: Units of each factor's statistic, for the verdict sentences.
_UNITS = {"orientation": "°", "timing": " ms", "noise": " (log background rate)"}
#: A hot-pixel gap: at least this ratio of hot pixels per sequence, and one more.
_HOT_RATIO = 1.5
#: Windows per side below which :func:`infer_scene` warns that its standard errors are unreliable.
MIN_WINDOWS = 8


class SmallSampleWarning(UserWarning):
    """:func:`infer_scene` compared fewer than :data:`MIN_WINDOWS` windows on a side: its
    standard errors, and so its verdicts, are unreliable (the message says how many).

    Example:
        >>> import warnings
        >>> frames = torch.poisson(torch.full((3, 12, 2, 8, 8), 0.3), generator=torch.Generator().manual_seed(0))
        >>> with warnings.catch_warnings(record=True) as caught:
        ...     warnings.simplefilter("always")
        ...     _ = infer_scene(frames, frames)
        >>> type(caught[0].message).__name__
        'SmallSampleWarning'
    """

_QUIET_FRAMES = 4
_ONSET_FRACTION = 0.2
_CONTACT_SHARE = 0.25


def _as_frames(value: object, name: str) -> Tensor:
    if isinstance(value, Tensor):
        frames = value
    elif isinstance(value, Sequence) and value and all(isinstance(v, Tensor) for v in value):
        frames = torch.stack(list(value))
    else:
        raise TypeError(f"{name} must be frames (N, T, 2, H, W) or a list of (T, 2, H, W) tensors, got {describe(value)}")
    frames = check_frames(frames, name)
    if frames.dim() != 5 or frames.shape[0] < 2:
        raise ValueError(f"{name} must hold at least 2 sequences (N, T, 2, H, W), got {tuple(frames.shape)}")
    if frames.shape[1] < _QUIET_FRAMES + 2:
        raise ValueError(f"{name} needs at least {_QUIET_FRAMES + 2} frames per sequence, got {frames.shape[1]}")
    if frames.is_floating_point() and not bool(torch.isfinite(frames).all()):
        bad = (~torch.isfinite(frames)).flatten(1).any(1).nonzero().flatten().tolist()
        raise ValueError(
            f"{name} holds NaN or Inf counts (sequences {bad[:10]}{'...' if len(bad) > 10 else ''}); the statistics "
            "would compare nothing and report no gap"
        )
    return frames


def sequence_statistics(frames: Tensor, *, frame_ms: float = 10.0) -> dict[str, Tensor]:
    """Per-sequence traces of each factor, computed from the frames alone (no labels).

    Args:
        frames: event counts ``(N, T, 2, H, W)``.
        frame_ms: frame length, for the onset in milliseconds.

    Returns:
        A dict of float64 ``(N,)`` tensors: ``angle_deg`` (contact axis, counter-clockwise
        on the displayed image, in (-90, 90]), ``angle_abs_deg``, ``width_px`` and
        ``length_px`` (twice the weighted median distance of the contact pixels from the
        strip's median line, across and along the axis: the half-width and half-length),
        ``onset_ms``, ``background`` (events per pixel and frame, both polarities, in the
        quietest frames: a little below the mean rate, as the quietest are chosen),
        ``log_background``, ``hot_pixels`` (pixels firing in every quiet frame), and
        ``quiet`` ``(N, k)`` int64: the indices of the quietest frames.

    Example:
        >>> frames = torch.zeros(2, 8, 2, 20, 20)
        >>> frames[:, 3:, 0, 8:11, 2:18] = 3.0  # a horizontal strip from frame 3
        >>> stats = sequence_statistics(frames)
        >>> stats["angle_deg"].tolist(), stats["onset_ms"].tolist()
        ([0.0, 0.0], [27.0, 27.0])
    """
    frames = check_frames(frames)
    n, t, _, h, w = frames.shape
    counts = frames.double()
    totals = counts.sum((2, 3, 4))  # (N, T)
    quiet = totals.argsort(1)[:, :_QUIET_FRAMES]
    quiet_frames = counts.sum(2).gather(1, quiet.view(n, -1, 1, 1).expand(n, quiet.shape[1], h, w))  # (N, k, H, W)
    background = quiet_frames.mean((1, 2, 3))  # events per pixel and frame
    hot = (quiet_frames > 0).all(1).sum((1, 2)).double()
    # contact pixels: totals well above what the background gives a pixel over T frames
    pixel_totals = counts.sum((1, 2))  # (N, H, W)
    expected = background.view(n, 1, 1) * t
    threshold = expected + 4 * expected.sqrt() + 4
    # and at least a quarter of the busiest pixel's (hot pixels excluded): a background pixel
    # far from the strip would own the second moments
    hot_mask = (quiet_frames > 0).all(1)
    busy = torch.where(hot_mask, torch.zeros_like(pixel_totals), pixel_totals).amax((1, 2))
    threshold = torch.maximum(threshold, _CONTACT_SHARE * busy.view(n, 1, 1))
    weight = torch.where((pixel_totals > threshold) & ~hot_mask, pixel_totals, torch.zeros_like(pixel_totals))
    ys = torch.arange(h, dtype=torch.float64)
    xs = torch.arange(w, dtype=torch.float64)
    mass = weight.sum((1, 2)).clamp_min(1e-12)
    cy = (weight.sum(2) * ys).sum(1) / mass
    cx = (weight.sum(1) * xs).sum(1) / mass
    dy = ys.view(1, h, 1) - cy.view(n, 1, 1)
    dx = xs.view(1, 1, w) - cx.view(n, 1, 1)
    c_yy = (weight * dy * dy).sum((1, 2)) / mass
    c_xx = (weight * dx * dx).sum((1, 2)) / mass
    c_xy = (weight * dx * dy).sum((1, 2)) / mass
    covariance = torch.stack([c_yy, c_xx, c_xy], 1)
    angle = torch.rad2deg(axis_radians(covariance)) + 0.0  # no -0.0
    # width and length: twice the weighted median distance from the strip's median line,
    # across and along the axis (a uniform strip of half-width b gives b); medians, not
    # second moments, so that scattered background pixels cannot own them
    radians = torch.deg2rad(angle)
    sin, cos = radians.sin().view(n, 1, 1), radians.cos().view(n, 1, 1)
    x_grid, y_grid = xs.view(1, 1, w), ys.view(1, h, 1)
    across = (x_grid * sin + y_grid * cos).expand(n, h, w)  # y down: the normal is (sin, cos)
    along = (x_grid * cos - y_grid * sin).expand(n, h, w)
    flat = weight.reshape(n, -1)
    width = 2 * _weighted_median((across.reshape(n, -1) - _weighted_median(across.reshape(n, -1), flat).unsqueeze(1)).abs(), flat)
    length = 2 * _weighted_median((along.reshape(n, -1) - _weighted_median(along.reshape(n, -1), flat).unsqueeze(1)).abs(), flat)
    # timing: the contact pixels' event rate (background removed) first reaches a fraction
    # of its peak, interpolated between frame centres (the release is no reference: a slow
    # contact's release runs past the end of the recording)
    contact = (weight > 0).double()  # (N, H, W)
    rate = (torch.einsum("nthw,nhw->nt", counts.sum(2), contact) - (background * contact.sum((1, 2))).view(n, 1))
    rate = rate.clamp_min(0)
    level = (_ONSET_FRACTION * rate.max(1).values).view(n, 1)
    onset = _crossing(rate, level) * frame_ms
    return {
        "angle_deg": angle,
        "angle_abs_deg": angle.abs(),
        "width_px": width,
        "length_px": length,
        "onset_ms": onset + frame_ms / 2,
        "background": background,
        "log_background": background.clamp_min(1e-9).log(),
        "hot_pixels": hot,
        "quiet": quiet,
    }


#: Share trimmed from each end for the location estimates (Yuen's trimmed mean): a contact
#: too weak to rise above the background gives a wild onset or angle, and must not decide.
_TRIM = 0.2


def _weighted_median(values: Tensor, weights: Tensor) -> Tensor:
    """(N,) weighted median of each row of ``values`` (N, M) with ``weights`` (N, M) ≥ 0
    (0 for a row without weight)."""
    order = values.argsort(1)
    cumulative = weights.gather(1, order).cumsum(1)
    half = cumulative[:, -1:] / 2
    index = (cumulative < half).sum(1, keepdim=True).clamp_max(values.shape[1] - 1)
    median = values.gather(1, order.gather(1, index)).squeeze(1)
    return torch.where(cumulative[:, -1] > 0, median, torch.zeros_like(median))


def _crossing(rate: Tensor, level: Tensor) -> Tensor:
    """(N,) fractional frame index where each row of ``rate`` first reaches ``level`` (N, 1),
    interpolated linearly from the frame before."""
    n = rate.shape[0]
    first = (rate >= level).double().argmax(1)
    before = (first - 1).clamp_min(0)
    r0, r1 = rate.gather(1, before.view(n, 1)).squeeze(1), rate.gather(1, first.view(n, 1)).squeeze(1)
    step = ((level.squeeze(1) - r0) / (r1 - r0).clamp_min(1e-12)).clamp(0, 1)
    return torch.where(first > 0, before.double() + step, first.double())


def _summary(values: Tensor) -> dict[str, float]:
    """20 %-trimmed mean and its standard error (Yuen: winsorised std / ((1 - 2γ)√n))."""
    n = values.numel()
    ordered = values.double().sort().values
    g = int(math.floor(_TRIM * n))
    trimmed = ordered[g : n - g] if n - 2 * g > 0 else ordered
    winsorised = ordered.clamp(float(trimmed[0]), float(trimmed[-1]))
    std = float(winsorised.std()) if n > 1 else 0.0
    se = std / ((1 - 2 * g / n) * math.sqrt(n)) if n else 0.0
    return {
        "mean": float(trimmed.mean()),
        "std": std,
        "se": se,
        "n": n,
        "min": float(ordered[0]),
        "max": float(ordered[-1]),
    }


def difference_test(a: dict[str, Any], b: dict[str, Any], difference: float, se: float, min_effect: float,
                    z_gap: float) -> dict[str, Any]:
    """The gap test between two sessions' summaries, as every factor of :func:`infer_scene` runs it.

    Args:
        a, b: the training and deployment summaries; each needs ``n`` (how many windows or
            recordings it summarises), the rest is reported as given.
        difference: the deployment's location minus the training's.
        se: the standard error of ``difference``.
        min_effect: the smallest ``|difference|`` that matters.
        z_gap: the ``|z|`` a difference must exceed.

    Returns:
        ``{"train": a, "deploy": b, "difference", "se", "z", "resolvable", "gap"}``: resolvable
        when both sides hold at least 2 and the standard error is positive (or both hold at
        least ``MIN_WINDOWS``); a gap when resolvable, ``|z| > z_gap`` and
        ``|difference| >= min_effect``.

    Example:
        >>> test = difference_test({"n": 10}, {"n": 12}, 8.0, 2.0, 3.0, 3.0)
        >>> test["z"], test["gap"]
        (4.0, True)
        >>> difference_test({"n": 1}, {"n": 12}, 8.0, 2.0, 3.0, 3.0)["resolvable"]
        False
    """
    # a zero standard error resolves nothing from a few windows (one window, or a handful that happen
    # to agree): no z, no gap; from MIN_WINDOWS a side, every window agreeing is evidence itself
    resolvable = a["n"] >= 2 and b["n"] >= 2 and (se > 0 or min(a["n"], b["n"]) >= MIN_WINDOWS)
    z = (difference / se if se > 0 else math.copysign(math.inf, difference) if difference else 0.0) \
        if resolvable else math.nan
    return {
        "train": a,
        "deploy": b,
        "difference": difference,
        "se": se,
        "z": z,
        "resolvable": resolvable,
        "gap": bool(resolvable and abs(z) > z_gap and abs(difference) >= min_effect),
    }


def _compare(train: Tensor, deploy: Tensor, min_effect: float, z_gap: float) -> dict[str, Any]:
    a, b = _summary(train), _summary(deploy)
    return difference_test(a, b, b["mean"] - a["mean"], math.sqrt(a["se"] ** 2 + b["se"] ** 2), min_effect, z_gap)


def _verdicts(evidence: dict[str, Any], z_gap: float, n_deploy: int) -> dict[str, str]:
    """Per frame-based factor: "gap", "no gap", or "not resolvable from N unlabeled deployment windows"."""
    out = {}
    for factor, (_, min_effect) in FACTOR_TESTS.items():
        test = evidence[factor]
        limit = z_gap * test["se"]
        test["resolvable_limit"] = limit
        if not test["resolvable"]:
            out[factor] = (f"not resolvable from {test['train']['n']} training and {test['deploy']['n']} deployment "
                           f"windows: the standard error is {test['se']:.3g}; give at least 2 windows a side with "
                           "different values (more recordings, or more windows per recording with fewer frames each)")
        elif test["gap"]:
            out[factor] = "gap"
        elif limit > min_effect and abs(test["difference"]) < limit:
            source = (f"{test['deploy']['n']} {test['source']}" if "source" in test
                      else f"{n_deploy} unlabeled deployment windows")
            out[factor] = (f"not resolvable from {source}: a difference below "
                           f"{limit:.3g}{_UNITS[factor]} would not be seen (measured {test['difference']:+.3g})")
        else:
            out[factor] = "no gap"
    return out


def _sizes(value: object, name: str) -> tuple[float, ...] | None:
    if value is None:
        return None
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        value = (value,)
    if isinstance(value, Tensor):
        value = value.flatten().tolist()
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or not value:
        raise TypeError(f"{name} must be object sizes (a number or a sequence of numbers), got {describe(value)}")
    sizes = tuple(float(v) for v in value)
    if not all(s > 0 and math.isfinite(s) for s in sizes):
        raise ValueError(f"{name} must hold positive sizes, got {value!r}")
    return sizes


def infer_scene(
    train: Tensor | Sequence[Tensor],
    deploy: Tensor | Sequence[Tensor],
    *,
    train_sizes: float | Sequence[float] | None = None,
    deploy_sizes: float | Sequence[float] | None = None,
    frame_ms: float = 10.0,
    z_gap: float = 3.0,
    timing: Mapping[str, Any] | None = None,
) -> Scene:
    """Estimate each factor in training and deployment frames and declare the gaps between them.

    No label is read: ``deploy`` may be recordings without labels. See the module docstring
    for the estimators and why size comes from the object sizes you give.

    Args:
        train: training frames ``(N, T, 2, H, W)`` (or a list of ``(T, 2, H, W)``).
        deploy: deployment frames, same layout (unlabeled).
        train_sizes: the training object sizes (a number or a sequence, each size once or
            one per sequence); with ``deploy_sizes``, a size gap is declared when a
            deployment size is not among the training sizes.
        deploy_sizes: the deployment object sizes (one size for the stretch target).
        frame_ms: frame length in milliseconds (timing in ms, shifts in frames).
        z_gap: the Welch z a difference must exceed to be a gap.
        timing: a timing test measured another way (see *Timing measured another way* in
            the module docstring), or ``None`` for the onset test alone.

    Shape:
        - train: ``(N, T, 2, H, W)`` or a list of ``(T, 2, H, W)``.
        - deploy: ``(M, T, 2, H, W)`` or a list of ``(T, 2, H, W)``, the same ``(H, W)``.

    Returns:
        A :class:`~event_transforms.Scene` whose :attr:`~event_transforms.Scene.gaps` are
        the factors that differ beyond their estimation error and whose policy uses the
        estimated ranges: a rotation over ± the deployment's largest contact angle; a frame
        shift by the rounded onset difference in frames (a TES of one frame moving that
        fraction of the events when the difference is under half a frame); the deployment's
        quietest frames as a noise bank; a stretch to the deployment size. ``scene.evidence``
        holds, per factor, the training and deployment summaries (mean, std, standard
        error, n, min, max), their difference, its standard error, z, the verdict and the
        ``resolvable_limit`` (``z_gap`` standard errors); ``evidence["verdicts"]`` says per
        factor "gap", "no gap" or "not resolvable from N unlabeled deployment windows: ..." (see
        the module docstring's detection limits). With a resolvable ``timing``,
        ``evidence["timing"]`` is that test and the onset test moves to
        ``evidence["timing"]["onset"]``.

    Example:
        >>> g = torch.Generator().manual_seed(0)
        >>> def recordings(n, start):
        ...     frames = torch.poisson(torch.full((n, 12, 2, 16, 20), 0.05), generator=g)
        ...     for i in range(n):
        ...         s = start + int(torch.randint(0, 2, (), generator=g))
        ...         frames[i, s:s + 5, 0, 7:9, 3:17] += 4.0  # a horizontal strip
        ...     return frames
        >>> scene = infer_scene(recordings(16, 2), recordings(16, 5), train_sizes=(12.0, 18.0), deploy_sizes=15.0)
        >>> scene.gaps, scene.lag_shifts
        (('timing', 'size'), (3,))
    """
    train_frames, deploy_frames = _as_frames(train, "train"), _as_frames(deploy, "deploy")
    if train_frames.shape[1:] != deploy_frames.shape[1:]:
        raise ValueError(
            f"train and deploy must share (T, 2, H, W), got {tuple(train_frames.shape[1:])} and "
            f"{tuple(deploy_frames.shape[1:])}"
        )
    if not (isinstance(frame_ms, (int, float)) and frame_ms > 0 and math.isfinite(frame_ms)):
        raise ValueError(f"frame_ms must be a positive number, got {frame_ms!r}")
    if not (isinstance(z_gap, (int, float)) and z_gap > 0):
        raise ValueError(f"z_gap must be a positive number, got {z_gap!r}")
    fewest = min(train_frames.shape[0], deploy_frames.shape[0])
    if fewest < MIN_WINDOWS:
        warn_at_caller(SmallSampleWarning(  # at the user's line, through any wrapper of the package
            f"infer_scene compares {train_frames.shape[0]} training and {deploy_frames.shape[0]} deployment "
            f"windows; below {MIN_WINDOWS} a side the standard errors, and so the verdicts, are unreliable"))
    a = sequence_statistics(train_frames, frame_ms=frame_ms)
    b = sequence_statistics(deploy_frames, frame_ms=frame_ms)
    evidence: dict[str, Any] = {}
    for factor, (statistic, min_effect) in FACTOR_TESTS.items():
        evidence[factor] = _compare(a[statistic], b[statistic], min_effect, z_gap)
        evidence[factor]["statistic"] = statistic
    hot = _compare(a["hot_pixels"], b["hot_pixels"], 1.0, z_gap)
    hot["gap"] = bool(hot["gap"] and hot["deploy"]["mean"] >= _HOT_RATIO * hot["train"]["mean"])
    evidence["noise"]["hot_pixels"] = hot
    evidence["noise"]["background_gap"] = evidence["noise"]["gap"]
    evidence["noise"]["gap"] = bool(evidence["noise"]["gap"] or hot["gap"])
    evidence["noise"]["background"] = {"train": _summary(a["background"]), "deploy": _summary(b["background"])}
    width = _compare(a["width_px"], b["width_px"], 0.0, z_gap)
    width["ratio"] = width["deploy"]["mean"] / max(width["train"]["mean"], 1e-12)
    width["ratio_se"] = width["ratio"] * math.sqrt(
        (width["deploy"]["se"] / max(width["deploy"]["mean"], 1e-12)) ** 2
        + (width["train"]["se"] / max(width["train"]["mean"], 1e-12)) ** 2
    )
    sizes_a, sizes_b = _sizes(train_sizes, "train_sizes"), _sizes(deploy_sizes, "deploy_sizes")
    size_gap = sizes_a is not None and sizes_b is not None and not set(sizes_b) <= set(sizes_a)
    evidence["size"] = {"width_px": width, "train_sizes": sizes_a, "deploy_sizes": sizes_b, "gap": size_gap}
    evidence["orientation"]["angle_deg"] = {"train": _summary(a["angle_deg"]), "deploy": _summary(b["angle_deg"])}
    if timing is not None:
        missing = [key for key in ("resolvable", "gap", "difference", "source") if key not in timing]
        if not isinstance(timing, Mapping) or missing:
            raise TypeError(f"timing must be a mapping with the keys of difference_test and a source, got "
                            f"{describe(timing)}" + (f" without {missing}" if isinstance(timing, Mapping) else ""))
        timing = dict(timing)
        if timing["resolvable"]:
            timing["onset"] = evidence["timing"]
            evidence["timing"] = timing
        else:
            evidence["timing"]["alternative"] = timing
    evidence["verdicts"] = _verdicts(evidence, z_gap, deploy_frames.shape[0])
    if timing is not None and not timing["resolvable"] and timing.get("verdict"):
        evidence["verdicts"]["timing"] += f"; {timing['verdict']}"

    kwargs: dict[str, Any] = {}
    if evidence["timing"]["gap"]:
        frames_late = evidence["timing"]["difference"] / frame_ms
        shift = int(round(frames_late))
        if shift != 0:
            kwargs["lag_shifts"] = (shift,)
        else:
            kwargs["lag_shifts"] = (1 if frames_late > 0 else -1,)
            kwargs["lag_fraction"] = min(abs(frames_late), 1.0)
    if evidence["orientation"]["gap"]:
        kwargs["orientation_deg"] = float(b["angle_abs_deg"].max())
    if evidence["noise"]["gap"]:
        n, k = b["quiet"].shape
        kwargs["noise"] = deploy_frames.gather(
            1, b["quiet"].view(n, k, 1, 1, 1).expand(n, k, *deploy_frames.shape[2:])
        ).reshape(n * k, *deploy_frames.shape[2:]).clone()
    if size_gap:
        if len(set(sizes_b)) != 1:  # type: ignore[arg-type]
            raise ValueError(f"deploy_sizes must hold one size to stretch to, got {deploy_sizes!r}")
        kwargs.update(training_sizes=tuple(sorted(set(sizes_a))), target_size=sizes_b[0])  # type: ignore[index,arg-type]
    return Scene(frame_ms=frame_ms, evidence=evidence, **kwargs)
