"""Lags from labelled recordings: when each recording's events follow its force.

A recording with force labels shows its lag directly. The contact strip's half-width grows
as √F (Hertz line contact), and each frame's OFF − ON event count is proportional to how
much the strip grew (or shrank) during that frame, as the membrane saw it. So the lag of a
recording is the delay ``L`` that best aligns the events with the force:

- **events**: ``s[t]`` = OFF − ON events of frame ``t`` (channel 0 minus channel 1, summed
  over the pixels);
- **force**: the membrane force ``F_m`` follows the labels through a first-order lag,
  τ dF_m/dt = F − F_m, with the time constant ρ·τ while the membrane relaxes (a viscous
  membrane relaxes more slowly than it is pressed), the labels interpolated linearly
  between the frame centres (where a force/torque sensor reads them) and held beyond
  them; ``u[t] = R((t + 1)·Δ − d) − R(t·Δ − d)`` is the change of R = √F_m over frame
  ``t``'s interval ``[t·Δ, (t + 1)·Δ)``, delayed by ``d`` (√F keeps a small negative
  reading's sign);
- **fit**: the (d, τ, ρ) of the grid (d in ``[-max_lag_ms, max_lag_ms]`` by Δ/20, (τ, ρ)
  in :data:`MEMBRANE_GRID`) whose Pearson correlation |corr(s, u)| is largest, d refined
  between grid points by a parabola. The absolute value makes the estimate independent
  of which polarity a camera gives a pressing contact; the fit's sign is reported.
- **lag** = d + τ: the mean lag of the pressing contact's events (a first-order lag delays
  a ramp by exactly τ); ``release_lag_ms`` = d + ρ·τ is reported beside it.

Why fit τ rather than take the peak of a plain cross-correlation: the peak sits at the
*mode* of the membrane's response, about 0.7 τ for a ramp much longer than τ, so a slow
membrane's lag came out ~5 ms short (on ``paper-membrane``'s deployment, τ 10–20 ms, the
sessions' difference measured 5 ms against 9 ms true, half a frame: the shift's rounding
then decides by chance). The correlation compares the change of √F over each frame's own
interval, so a frame's events are not compared with a reading half a frame away (a
forward difference ``√F[t + 1] − √F[t]`` would put every lag half a frame late).

Measured on the benchmark's simulated sessions (48 training and 24 validation grasps each):
per-recording error against the drawn delay + τ within 1.5–2.5 ms sd, with a bias of
+1 to +1.7 ms common to every session (the DVS threshold fires early in a pixel's
transition), which cancels in the sessions' difference.

A recording whose force never changes (a window of a steady hold) or whose frames hold no
polarity difference has no lag: its entry is NaN and :func:`session_lag` counts it as
uninformative (never silently dropped).

Per session, :func:`session_lag` gives the median lag, its spread (1.4826 × the median
absolute deviation, a robust standard deviation) and the median's standard error
(1.2533 × spread / √n). :func:`~event_transforms.infer_scene` compares the sessions'
medians with these standard errors.
"""

from __future__ import annotations

__all__ = ["MEMBRANE_GRID", "recording_lags", "session_lag", "as_labelled", "lag_test", "infer_scene_with_lags"]

import math
from collections.abc import Sequence
from typing import Any

import torch
from torch import Tensor

from .._validation import check_frames, describe
from ..inference import FACTOR_TESTS, difference_test, infer_scene
from ..scenes import Scene

#: Grid steps per frame of the delay search, and fine-grid substeps per frame of the membrane.
_STEPS_PER_FRAME = 20
_SUBSTEPS = 10
#: The membrane models fitted: (τ in ms, release ratio ρ); the membrane force follows the
#: force through a first-order lag of time constant τ while pressed and ρ·τ while relaxing.
MEMBRANE_GRID: tuple[tuple[float, float], ...] = ((0.0, 1.0),) + tuple(
    (tau, ratio) for tau in (1.0, 2.0, 3.0, 4.0, 6.0, 8.0, 10.0, 12.0, 15.0, 18.0, 22.0, 26.0, 30.0)
    for ratio in (1.0, 2.0, 3.0, 4.0))
#: Spread of a normal sample from its median absolute deviation, and the median's
#: standard error relative to the mean's (√(π/2)).
_MAD_TO_SD = 1.4826
_MEDIAN_SE = math.sqrt(math.pi / 2)


def _recordings(value: object, name: str, *, frames: bool) -> list[Tensor]:
    """A batch tensor or a list of per-recording tensors, as a list (no copy)."""
    rank = 5 if frames else 2
    if isinstance(value, Tensor):
        if value.dim() != rank:
            shape = "(N, T, 2, H, W)" if frames else "(N, T)"
            raise ValueError(f"{name} must be {shape} or a list of recordings, got shape {tuple(value.shape)}")
        items = list(value.unbind(0))
    elif isinstance(value, Sequence) and not isinstance(value, (str, bytes)) and value \
            and all(isinstance(v, Tensor) for v in value):
        items = list(value)
    else:
        kind = "frames (N, T, 2, H, W) or a list of (T, 2, H, W)" if frames else "forces (N, T) or a list of (T,)"
        raise TypeError(f"{name} must be {kind} tensors, got {describe(value)}")
    for i, item in enumerate(items):
        if frames:
            check_frames(item, f"{name}[{i}]")
            if item.dim() != 4:
                raise ValueError(f"{name}[{i}] must be one recording's frames (T, 2, H, W), got {tuple(item.shape)}")
        else:
            if item.dim() != 1 or not (item.is_floating_point() or item.dtype in (torch.int32, torch.int64)):
                raise ValueError(f"{name}[{i}] must be one recording's forces (T,) of numbers, got "
                                 f"{describe(item)}")
            if not bool(torch.isfinite(item.double()).all()):
                raise ValueError(f"{name}[{i}] holds NaN or Inf forces: {describe(item)}")
    return items


def as_labelled(value: object, name: str) -> tuple[list[Tensor], list[Tensor]]:
    """Check labelled recordings: a pair ``(frames, forces)`` with one force per frame.

    Args:
        value: ``(frames, forces)``: frames ``(N, T, 2, H, W)`` or a list of
            ``(T_i, 2, H, W)``, forces ``(N, T)`` or a list of ``(T_i,)`` (recordings may differ
            in length; each recording's forces must match its frames).
        name: the argument's name, for the errors.

    Returns:
        The per-recording frames and forces, as lists.

    Example:
        >>> frames, forces = as_labelled((torch.zeros(2, 6, 2, 4, 4), torch.zeros(2, 6)), "labelled")
        >>> len(frames), tuple(forces[0].shape)
        (2, (6,))
    """
    if not (isinstance(value, (tuple, list)) and len(value) == 2):
        raise TypeError(f"{name} must be a pair (frames, forces), got {describe(value)}")
    frames = _recordings(value[0], f"{name} frames", frames=True)
    forces = _recordings(value[1], f"{name} forces", frames=False)
    if len(frames) != len(forces):
        raise ValueError(f"{name}: {len(frames)} recordings of frames but {len(forces)} of forces")
    for i, (f, force) in enumerate(zip(frames, forces)):
        if f.shape[0] != force.shape[0]:
            raise ValueError(f"{name}: recording {i} has {f.shape[0]} frames but {force.shape[0]} force readings; "
                             "give one reading per frame (at the frame's centre)")
        if f.shape[0] < 3:
            raise ValueError(f"{name}: recording {i} has {f.shape[0]} frames; a lag needs at least 3")
    return frames, forces


def _interpolate(values: Tensor, times: Tensor, frame_ms: float) -> Tensor:
    """``values`` (..., T) sampled at the frame centres, linearly interpolated at ``times``
    (M,), holding the end values beyond them: (..., M)."""
    t = values.shape[-1]
    position = (times / frame_ms - 0.5).clamp(0, t - 1)
    low = position.floor().long().clamp_max(t - 2)
    weight = position - low
    return values[..., low] * (1 - weight) + values[..., low + 1] * weight


def _membrane(force: Tensor, frame_ms: float) -> Tensor:
    """√ of the membrane force of every (τ, ρ) of :data:`MEMBRANE_GRID` on a fine grid
    (``_SUBSTEPS`` per frame, from 0 to T·Δ): ``force`` (n, T) -> (n, C, T·_SUBSTEPS + 1)."""
    n, t = force.shape
    step = frame_ms / _SUBSTEPS
    fine = _interpolate(force, torch.arange(t * _SUBSTEPS + 1, dtype=torch.float64) * step, frame_ms)
    tau = torch.tensor([c[0] for c in MEMBRANE_GRID], dtype=torch.float64)
    ratio = torch.tensor([c[1] for c in MEMBRANE_GRID], dtype=torch.float64)
    press = torch.where(tau > 0, 1 - torch.exp(-step / tau.clamp_min(1e-12)), torch.ones_like(tau))
    relax = torch.where(tau > 0, 1 - torch.exp(-step / (tau * ratio).clamp_min(1e-12)), torch.ones_like(tau))
    membrane = fine[:, :1].expand(n, len(MEMBRANE_GRID)).clone()
    out = [membrane]
    for k in range(1, fine.shape[1]):
        target = fine[:, k : k + 1]
        membrane = membrane + torch.where(target < membrane, relax, press) * (target - membrane)
        out.append(membrane)
    stacked = torch.stack(out, -1)
    return stacked.sign() * stacked.abs().sqrt()


def recording_lags(
    labelled: tuple[Tensor | Sequence[Tensor], Tensor | Sequence[Tensor]],
    *,
    frame_ms: float = 10.0,
    max_lag_ms: float = 50.0,
) -> dict[str, Tensor]:
    """The lag of each labelled recording's events behind its force (see the module docstring).

    Args:
        labelled: ``(frames, forces)``: event counts ``(N, T, 2, H, W)`` (channel 0 OFF, 1 ON)
            or a list of ``(T_i, 2, H, W)``, and the force read at each frame's centre,
            ``(N, T)`` or a list of ``(T_i,)``.
        frame_ms: frame length in milliseconds.
        max_lag_ms: the delay grid's half-range: delays in ``[-max_lag_ms, max_lag_ms]``.

    Returns:
        float64 ``(N,)`` tensors: ``lag_ms`` (delay + τ: the mean lag of the pressing
        contact; NaN where the force never changes or the frames hold no OFF − ON
        difference), ``delay_ms``, ``tau_ms``, ``release_ratio`` (the fitted membrane),
        ``release_lag_ms`` (delay + ρ·τ), ``correlation`` (the signed Pearson correlation
        of the fit) and ``at_edge`` (1.0 where the best delay is the grid's end: widen
        ``max_lag_ms``).

    Example:
        >>> force = torch.zeros(2, 20)
        >>> force[:, 5:15] = torch.tensor([1, 4, 9, 16, 16, 16, 16, 9, 4, 1.0])  # √F: a ramp up and down
        >>> frames = torch.zeros(2, 20, 2, 4, 4)
        >>> change = force.sqrt().diff(dim=1)  # √F grows by 1 per frame on the way up
        >>> frames[:, 2:, 0, 0, 0] = change[:, :-1].clamp_min(0)  # OFF events 1.5 frames late
        >>> frames[:, 2:, 1, 0, 0] = (-change[:, :-1]).clamp_min(0)
        >>> [round(v) for v in recording_lags((frames, force))["lag_ms"].tolist()]
        [15, 15]
    """
    frames, forces = as_labelled(labelled, "labelled")
    if not (isinstance(frame_ms, (int, float)) and frame_ms > 0 and math.isfinite(frame_ms)):
        raise ValueError(f"frame_ms must be a positive number, got {frame_ms!r}")
    if not (isinstance(max_lag_ms, (int, float)) and max_lag_ms > 0 and math.isfinite(max_lag_ms)):
        raise ValueError(f"max_lag_ms must be a positive number, got {max_lag_ms!r}")
    step = frame_ms / _STEPS_PER_FRAME
    half = int(math.ceil(max_lag_ms / step))
    grid = torch.arange(-half, half + 1, dtype=torch.float64) * step  # (G,)
    fine_step = frame_ms / _SUBSTEPS
    keys = ("lag_ms", "delay_ms", "tau_ms", "release_ratio", "release_lag_ms", "correlation", "at_edge")
    results = {key: [math.nan] * len(frames) for key in keys}
    by_length: dict[int, list[int]] = {}
    for i, f in enumerate(frames):
        by_length.setdefault(f.shape[0], []).append(i)
    for t, members in by_length.items():
        roots = _membrane(torch.stack([forces[i].double() for i in members]), frame_ms)  # (n, C, K)
        starts = torch.arange(t, dtype=torch.float64) * frame_ms
        before = ((starts.view(1, t) - grid.view(-1, 1)) / fine_step).clamp(0, roots.shape[-1] - 1)  # (G, T)
        after = ((starts.view(1, t) + frame_ms - grid.view(-1, 1)) / fine_step).clamp(0, roots.shape[-1] - 1)
        for row, i in enumerate(members):
            counts = frames[i].double().sum((2, 3))  # (T, 2)
            signal = counts[:, 0] - counts[:, 1]
            signal = signal - signal.mean()
            root = roots[row]  # (C, K)

            def at(position: Tensor, root: Tensor = root) -> Tensor:
                low = position.floor().long().clamp_max(root.shape[-1] - 2)
                weight = position - low
                return root[:, low] * (1 - weight) + root[:, low + 1] * weight  # (C, G, T)

            change = at(after) - at(before)
            change = change - change.mean(-1, keepdim=True)
            norm = change.norm(dim=-1) * signal.norm()
            if float(norm.max()) == 0:
                results["at_edge"][i] = 0.0
                continue  # no force change or no polarity difference: no lag
            correlation = torch.where(norm > 0, (change @ signal) / norm.clamp_min(1e-300), torch.zeros_like(norm))
            combo, best = divmod(int(correlation.abs().flatten().argmax()), len(grid))
            delay = float(grid[best])
            if 0 < best < len(grid) - 1:  # a parabola through the peak and its neighbours
                y0, y1, y2 = (float(correlation[combo, best + k].abs()) for k in (-1, 0, 1))
                curvature = y0 - 2 * y1 + y2
                if curvature < 0:
                    delay += step * 0.5 * (y0 - y2) / curvature
            tau, ratio = MEMBRANE_GRID[combo]
            results["lag_ms"][i] = delay + tau
            results["delay_ms"][i] = delay
            results["tau_ms"][i] = tau
            results["release_ratio"][i] = ratio
            results["release_lag_ms"][i] = delay + ratio * tau
            results["correlation"][i] = float(correlation[combo, best])
            results["at_edge"][i] = float(best in (0, len(grid) - 1))
    return {key: torch.tensor(values, dtype=torch.float64) for key, values in results.items()}


def session_lag(lags: Tensor) -> dict[str, Any]:
    """The median of a session's per-recording lags, its spread and standard error.

    NaN entries (recordings without a measurable lag) are counted as ``uninformative``
    and left out of the median.

    Args:
        lags: per-recording lags ``(N,)`` in ms (:func:`recording_lags`' ``lag_ms``).

    Returns:
        ``median``, ``spread`` (1.4826 × MAD), ``se`` (1.2533 × spread / √n), ``n`` (the
        recordings with a lag), ``uninformative``, ``min``, ``max`` (NaN where ``n`` is 0;
        ``spread`` and ``se`` are 0 where ``n`` is 1).

    Example:
        >>> summary = session_lag(torch.tensor([18.0, 20.0, 22.0, float("nan")]))
        >>> summary["median"], summary["n"], summary["uninformative"], round(summary["spread"], 2)
        (20.0, 3, 1, 2.97)
    """
    if not isinstance(lags, Tensor) or lags.dim() != 1:
        raise TypeError(f"lags must be a 1-d tensor of per-recording lags, got {describe(lags)}")
    values = lags.double()
    known = values[~values.isnan()]
    n = known.numel()
    if n == 0:
        return {"median": math.nan, "spread": math.nan, "se": math.nan, "n": 0,
                "uninformative": int(values.numel()), "min": math.nan, "max": math.nan}
    ordered = known.sort().values
    middle = n // 2
    median = float(ordered[middle]) if n % 2 else float(ordered[middle - 1: middle + 1].mean())
    deviations = (ordered - median).abs().sort().values
    mad = float(deviations[middle]) if n % 2 else float(deviations[middle - 1: middle + 1].mean())
    spread = _MAD_TO_SD * mad
    return {
        "median": median,
        "spread": spread,
        "se": _MEDIAN_SE * spread / math.sqrt(n),
        "n": n,
        "uninformative": int(values.numel() - n),
        "min": float(ordered[0]),
        "max": float(ordered[-1]),
    }


#: The smallest lag difference that matters (ms): the onset test's.
_LAG_EFFECT = FACTOR_TESTS["timing"][1]


def lag_test(
    labelled_train: tuple[Tensor | Sequence[Tensor], Tensor | Sequence[Tensor]],
    labelled_deploy: tuple[Tensor | Sequence[Tensor], Tensor | Sequence[Tensor]],
    *,
    grid: Sequence[int] | None = None,
    frame_ms: float = 10.0,
    max_lag_ms: float = 50.0,
    z_gap: float = 3.0,
) -> dict[str, Any]:
    """The timing test from labelled recordings, in the form :func:`event_transforms.infer_scene`
    takes as ``timing=``: per-recording lags (:func:`recording_lags`), each session's median
    (:func:`session_lag`), their difference and its z.

    A timing gap where ``|z| > z_gap`` and the difference is at least 3 ms (the onset test's
    smallest effect); with fewer than 2 recordings with a lag on a side (or a zero standard
    error from a few), ``resolvable`` is false and ``verdict`` says what would resolve it.

    Args:
        labelled_train, labelled_deploy: ``(frames, forces)`` of each session, as
            :func:`recording_lags` takes them.
        grid: the ``(2, H, W)`` every recording's frames must have (the unlabeled frames'),
            or ``None`` for any.
        frame_ms: frame length in milliseconds.
        max_lag_ms: the lag search's half-range.
        z_gap: the ``|z|`` a difference must exceed.

    Returns:
        :func:`~event_transforms.inference.difference_test`'s keys (``train``/``deploy`` hold the
        median lag, also under ``mean``, its ``spread`` under ``std``, and its standard error),
        ``statistic`` ``"lag_ms"``, ``source`` ``"labelled recordings"``, ``lags`` (the
        per-recording lags, release lags and correlations), ``at_edge`` and, when not
        resolvable, ``verdict``.

    Example:
        >>> force = torch.zeros(4, 20)
        >>> force[:, 5:15] = torch.tensor([1, 4, 9, 16, 16, 16, 16, 9, 4, 1.0])
        >>> def late(by):
        ...     frames = torch.zeros(4, 20, 2, 4, 4)
        ...     change = force.sqrt().diff(dim=1)
        ...     frames[:, by:, 0, 0, 0] = change[:, :20 - by].clamp_min(0)
        ...     frames[:, by:, 1, 0, 0] = (-change[:, :20 - by]).clamp_min(0)
        ...     return frames
        >>> test = lag_test((late(1), force), (late(3), force))
        >>> test["source"], round(test["difference"])
        ('labelled recordings', 20)
    """
    sides = {}
    for side, value in (("train", labelled_train), ("deploy", labelled_deploy)):
        name = f"labelled_{side}"
        frames, forces = as_labelled(value, name)
        for i, f in enumerate(frames):
            if grid is not None and tuple(f.shape[1:]) != tuple(grid):
                raise ValueError(f"{name}: recording {i} has frames of (2, H, W) = {tuple(f.shape[1:])}, the "
                                 f"unlabeled frames {tuple(grid)}; give one grid")
        sides[side] = recording_lags((frames, forces), frame_ms=frame_ms, max_lag_ms=max_lag_ms)
    a, b = session_lag(sides["train"]["lag_ms"]), session_lag(sides["deploy"]["lag_ms"])
    for summary in (a, b):  # the location every test reports under "mean", and its spread under "std"
        summary["mean"], summary["std"] = summary["median"], summary["spread"]
    difference = b["median"] - a["median"]
    se = math.sqrt(a["se"] ** 2 + b["se"] ** 2) if a["n"] and b["n"] else math.nan
    test: dict[str, Any] = {
        "statistic": "lag_ms",
        "source": "labelled recordings",
        **difference_test(a, b, difference, se, _LAG_EFFECT, z_gap),
        "lags": {side: {key: lags[key].tolist() for key in ("lag_ms", "release_lag_ms", "correlation")}
                 for side, lags in sides.items()},
        "at_edge": int(sum(float(lags["at_edge"].sum()) for lags in sides.values())),
    }
    if not test["resolvable"]:
        test["verdict"] = (
            f"labelled lags not resolvable from {a['n']} training and {b['n']} deployment labelled recordings with a "
            f"lag (standard error {se:.3g} ms): give at least 2 a side whose force changes, with different lags")
    return test


def infer_scene_with_lags(
    train: Tensor | Sequence[Tensor],
    deploy: Tensor | Sequence[Tensor],
    *,
    labelled_train: tuple[Tensor | Sequence[Tensor], Tensor | Sequence[Tensor]] | None = None,
    labelled_deploy: tuple[Tensor | Sequence[Tensor], Tensor | Sequence[Tensor]] | None = None,
    max_lag_ms: float = 50.0,
    frame_ms: float = 10.0,
    z_gap: float = 3.0,
    **kwargs: Any,
) -> Scene:
    """:func:`event_transforms.infer_scene`, with the timing test from labelled recordings.

    With labelled recordings of both sessions, the timing gap is measured from events against
    force (:func:`lag_test`) instead of the unlabeled onset; the onset test stays in
    ``evidence["timing"]["onset"]``, or decides when the lags are not resolvable (then kept
    under ``evidence["timing"]["alternative"]``, the verdict saying why). Without them, this is
    :func:`~event_transforms.infer_scene`.

    Args:
        train, deploy: the unlabeled frames, as :func:`~event_transforms.infer_scene` takes them.
        labelled_train: labelled training recordings ``(frames, forces)`` (frames
            ``(N, T, 2, H, W)`` or a list of ``(T_i, 2, H, W)``, forces ``(N, T)`` or a list of
            ``(T_i,)``, one reading per frame centre), or ``None``.
        labelled_deploy: labelled deployment recordings (for example the deployment's
            validation recordings), the same layout, or ``None``.
        max_lag_ms: the lag search's half-range.
        frame_ms, z_gap, **kwargs: passed to :func:`~event_transforms.infer_scene`.

    Example:
        >>> frames = torch.poisson(torch.full((8, 12, 2, 8, 8), 0.1), generator=torch.Generator().manual_seed(0))
        >>> infer_scene_with_lags(frames, frames.clone()).gaps
        ()
    """
    if (labelled_train is None) != (labelled_deploy is None):
        given, missing = ("labelled_train", "labelled_deploy") if labelled_deploy is None else (
            "labelled_deploy", "labelled_train")
        raise ValueError(f"{given} needs {missing}: lags are compared between the sessions, got {missing}=None")
    timing = None
    if labelled_train is not None and labelled_deploy is not None:
        grid = _grid_of(train)
        timing = lag_test(labelled_train, labelled_deploy, grid=grid, frame_ms=frame_ms, max_lag_ms=max_lag_ms,
                          z_gap=z_gap)
    return infer_scene(train, deploy, frame_ms=frame_ms, z_gap=z_gap, timing=timing, **kwargs)


def _grid_of(frames: Tensor | Sequence[Tensor]) -> tuple[int, ...] | None:
    """The ``(2, H, W)`` of unlabeled frames (a batch or a list), or ``None`` when there are none."""
    if isinstance(frames, Tensor):
        return tuple(frames.shape[2:]) if frames.dim() == 5 else tuple(frames.shape[1:])
    first = next(iter(frames), None)
    return tuple(first.shape[1:]) if isinstance(first, Tensor) else None
