"""Force baselines the network must beat: trivial ones and a physics model.

Each baseline is a small class with ``fit(frames, force) -> self`` and
``predict(frames) -> force`` on whole tensors, computed in float64 on the CPU:

- :class:`GlobalMean`: one number, the training mean force.
- :class:`PerFrameMean`: the training mean force at each frame index ``t`` (the grasp's
  average profile).
- :class:`CumulativeCountRidge`: ridge regression of ``force[t]`` on the cumulative OFF and
  ON event totals up to ``t`` and the totals of frame ``t``, plus one unpenalised intercept
  per frame index. A membrane pressed harder emits more events, so the running totals
  integrate the indentation; issue 9 found such a linear model beating the ConvLSTM.
- :class:`PhysicsLeastSquares`: least squares of ``force[t]`` on the running signed event
  total ``OFF - ON`` up to ``t`` and its square (the indentation and Hertz's nonlinearity),
  the OFF and ON totals of frame ``t``, and one intercept per frame index; optionally told
  each sequence's bolt diameter (issue 17: the competence bar of the reference network).

:func:`evaluate_baselines` fits them all on a training split and reports the validation
and test MSE (N²) of each, so they can appear as rows of a results table.

Example:
    >>> g = torch.Generator().manual_seed(0)
    >>> frames = torch.poisson(torch.full((6, 5, 2, 4, 3), 2.0), generator=g)
    >>> force = frames[:, :, 0].sum((-2, -1)).cumsum(1) / 10
    >>> data = (frames, force)
    >>> scores = evaluate_baselines(data, data, data)
    >>> sorted(scores)
    ['cumulative-count-ridge', 'global-mean', 'per-frame-mean', 'physics least-squares']
    >>> scores["cumulative-count-ridge"]["test_mse"] < scores["per-frame-mean"]["test_mse"]
    True
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import Tensor

__all__ = [
    "Baseline",
    "GlobalMean",
    "PerFrameMean",
    "CumulativeCountRidge",
    "PhysicsLeastSquares",
    "count_features",
    "physics_features",
    "evaluate_baselines",
    "stack_items",
]


def _check_frames(frames: object, name: str = "frames") -> Tensor:
    if not isinstance(frames, Tensor):
        raise TypeError(f"{name} must be a torch.Tensor, got {type(frames).__name__}")
    if frames.dim() != 5 or frames.shape[2] != 2:
        raise ValueError(f"{name}: expected (N, T, 2, H, W), got {tuple(frames.shape)}")
    if frames.is_complex() or frames.dtype == torch.bool:
        raise TypeError(f"{name} must hold real counts, got dtype {frames.dtype}")
    return frames


def _check_pair(frames: object, force: object, name: str = "") -> tuple[Tensor, Tensor]:
    frames = _check_frames(frames, f"{name}frames")
    if not isinstance(force, Tensor):
        raise TypeError(f"{name}force must be a torch.Tensor, got {type(force).__name__}")
    if force.shape != frames.shape[:2]:
        raise ValueError(
            f"{name}force: expected (N, T) = {tuple(frames.shape[:2])} to match frames, "
            f"got {tuple(force.shape)}"
        )
    if frames.shape[0] == 0:
        raise ValueError(f"{name}frames: need at least one sequence, got N = 0")
    return frames, force.detach().to("cpu", torch.float64)


def count_features(frames: Tensor) -> Tensor:
    """Per-frame event features ``(N, T, 4)`` in float64: cumulative OFF, cumulative ON,
    OFF in frame ``t``, ON in frame ``t``.

    Args:
        frames: event counts ``(N, T, 2, H, W)``, any real dtype (channel 0 OFF, 1 ON).

    Example:
        >>> frames = torch.ones(1, 3, 2, 2, 2, dtype=torch.int16)
        >>> count_features(frames)[0].tolist()
        [[4.0, 4.0, 4.0, 4.0], [8.0, 8.0, 4.0, 4.0], [12.0, 12.0, 4.0, 4.0]]
    """
    frames = _check_frames(frames)
    totals = frames.detach().to("cpu", torch.float64).sum(dim=(-2, -1))  # (N, T, 2)
    return torch.cat([totals.cumsum(dim=1), totals], dim=-1)


class Baseline:
    """Common interface: ``fit(frames, force) -> self``, ``predict(frames) -> force``."""

    name = "baseline"
    _steps: int | None = None

    def fit(self, frames: Tensor, force: Tensor) -> Baseline:  # pragma: no cover - abstract
        raise NotImplementedError

    def _predict(self, frames: Tensor) -> Tensor:  # pragma: no cover - abstract
        raise NotImplementedError

    def predict(self, frames: Tensor) -> Tensor:
        """Predicted force ``(N, T)``, float64 on the CPU."""
        if self._steps is None:
            raise RuntimeError(f"{type(self).__name__}.predict called before fit")
        frames = _check_frames(frames)
        return self._predict(frames)

    def _check_steps(self, frames: Tensor) -> None:
        if frames.shape[1] != self._steps:
            raise ValueError(
                f"frames: fitted on T = {self._steps} frames per sequence, got T = {frames.shape[1]}"
            )

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


class GlobalMean(Baseline):
    """Predict the training mean force, one number for every frame.

    Example:
        >>> frames = torch.zeros(2, 3, 2, 4, 4)
        >>> GlobalMean().fit(frames, torch.tensor([[0., 1, 2], [2, 3, 4]])).predict(frames[:1])
        tensor([[2., 2., 2.]], dtype=torch.float64)
    """

    name = "global-mean"

    def fit(self, frames: Tensor, force: Tensor) -> GlobalMean:
        frames, force = _check_pair(frames, force)
        self.mean_ = float(force.mean())
        self._steps = frames.shape[1]
        return self

    def _predict(self, frames: Tensor) -> Tensor:
        return torch.full(frames.shape[:2], self.mean_, dtype=torch.float64)


class PerFrameMean(Baseline):
    """Predict the training mean force at each frame index ``t`` (the mean profile).

    Example:
        >>> frames = torch.zeros(2, 3, 2, 4, 4)
        >>> PerFrameMean().fit(frames, torch.tensor([[0., 1, 2], [2, 3, 4]])).predict(frames[:1])
        tensor([[1., 2., 3.]], dtype=torch.float64)
    """

    name = "per-frame-mean"

    def fit(self, frames: Tensor, force: Tensor) -> PerFrameMean:
        frames, force = _check_pair(frames, force)
        self.profile_ = force.mean(dim=0)
        self._steps = frames.shape[1]
        return self

    def _predict(self, frames: Tensor) -> Tensor:
        self._check_steps(frames)
        return self.profile_.expand(frames.shape[0], -1).clone()


def _check_alpha(value: object, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
        math.isfinite(value) and value >= 0
    ):
        raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
    return float(value)


class CumulativeCountRidge(Baseline):
    """Ridge regression of force on cumulative event counts, with per-frame intercepts.

    Features of frame ``t`` of a sequence (:func:`count_features`): the OFF and ON totals
    summed over frames ``0..t``, and the OFF and ON totals of frame ``t``. Each feature is
    standardised with the training mean and standard deviation (over every frame of every
    sequence). The model is

    .. math::

        \\hat F_{n,t} = a_t + \\sum_k w_k z_{n,t,k}

    with one intercept ``a_t`` per frame index (one-hot ``t``, **not** penalised) and
    weights ``w`` minimising ``Σ (F - \\hat F)^2 + alpha ‖w‖²``, solved in closed form in
    float64 (``torch.linalg.solve`` on the normal equations).

    Choosing ``alpha`` (the documented rule): an explicit ``alpha`` is always used.
    ``alpha=None`` (default) means ``1.0`` when :meth:`fit` gets no validation data, and
    otherwise the value of ``alphas`` with the smallest validation MSE (the first on ties);
    the choice is kept in ``alpha_``. Features are standardised, so ``alpha`` is in units of
    "one training frame's worth of squared feature".

    Args:
        alpha: ridge penalty (>= 0) on the standardised feature weights, or ``None``.
        alphas: the grid searched on validation data when ``alpha`` is ``None``.

    Example:
        >>> g = torch.Generator().manual_seed(0)
        >>> frames = torch.poisson(torch.full((8, 6, 2, 3, 3), 1.0), generator=g)
        >>> features = count_features(frames)
        >>> force = 0.5 * features[..., 0] - 0.25 * features[..., 1] + 3.0
        >>> ridge = CumulativeCountRidge(alpha=1e-9).fit(frames, force)
        >>> bool((ridge.predict(frames) - force).abs().max() < 1e-6)
        True
    """

    name = "cumulative-count-ridge"

    def __init__(
        self, alpha: float | None = None, alphas: Sequence[float] = (0.01, 0.1, 1.0, 10.0, 100.0)
    ) -> None:
        self.alpha = None if alpha is None else _check_alpha(alpha, "alpha")
        if isinstance(alphas, (str, bytes)) or not isinstance(alphas, Sequence) or not alphas:
            raise ValueError(f"alphas must be a non-empty sequence of numbers >= 0, got {alphas!r}")
        self.alphas = tuple(_check_alpha(a, "alphas") for a in alphas)

    def _design(self, frames: Tensor) -> Tensor:
        """``(N*T, K + T)`` design: standardised features, then one-hot frame index."""
        z = (count_features(frames) - self.feature_mean_) / self.feature_std_
        n, steps, k = z.shape
        onehot = torch.eye(steps, dtype=torch.float64).expand(n, steps, steps)
        return torch.cat([z, onehot], dim=-1).reshape(n * steps, k + steps)

    def _solve(self, gram: Tensor, moment: Tensor, alpha: float) -> Tensor:
        penalty = torch.zeros(gram.shape[0], dtype=torch.float64)
        penalty[: self.feature_mean_.numel()] = alpha
        return torch.linalg.solve(gram + torch.diag(penalty), moment)

    def fit(
        self, frames: Tensor, force: Tensor, *, val: tuple[Tensor, Tensor] | None = None
    ) -> CumulativeCountRidge:
        """Fit on ``frames`` ``(N, T, 2, H, W)`` and ``force`` ``(N, T)``.

        Args:
            frames: training event counts.
            force: training force per frame.
            val: optional ``(frames, force)`` used only to pick ``alpha`` from ``alphas``
                (when ``alpha`` is ``None``).
        """
        frames, force = _check_pair(frames, force)
        features = count_features(frames).flatten(0, 1)
        self.feature_mean_ = features.mean(dim=0)
        std = features.std(dim=0, correction=0)
        self.feature_std_ = torch.where(std > 0, std, torch.ones_like(std))
        self._steps = frames.shape[1]
        design = self._design(frames)
        target = force.reshape(-1)
        gram, moment = design.T @ design, design.T @ target
        if self.alpha is not None or val is None:
            self.alpha_ = 1.0 if self.alpha is None else self.alpha
            self.validation_mse_: dict[float, float] = {}
        else:
            if not isinstance(val, (tuple, list)) or len(val) != 2:
                raise TypeError(f"val must be a (frames, force) pair, got {type(val).__name__}")
            val_frames, val_force = _check_pair(*val, name="val ")
            self._check_steps(val_frames)
            val_design = self._design(val_frames)
            self.validation_mse_ = {}
            for alpha in self.alphas:
                coef = self._solve(gram, moment, alpha)
                residual = val_design @ coef - val_force.reshape(-1)
                self.validation_mse_[alpha] = float(residual.square().mean())
            self.alpha_ = min(self.alphas, key=lambda a: self.validation_mse_[a])
        self.coef_ = self._solve(gram, moment, self.alpha_)
        return self

    def _predict(self, frames: Tensor) -> Tensor:
        self._check_steps(frames)
        return (self._design(frames) @ self.coef_).reshape(frames.shape[:2])

    def __repr__(self) -> str:
        return f"CumulativeCountRidge(alpha={self.alpha!r})"


def _check_diameters(diameters: object, n: int, name: str = "diameters") -> Tensor:
    if not isinstance(diameters, Tensor):
        try:
            diameters = torch.as_tensor(diameters, dtype=torch.float64)
        except (TypeError, ValueError):
            raise TypeError(f"{name} must be a tensor or sequence of N numbers, got {diameters!r:.80}") from None
    diameters = diameters.detach().to("cpu", torch.float64)
    if diameters.shape != (n,):
        raise ValueError(f"{name}: expected (N,) = ({n},), got {tuple(diameters.shape)}")
    if not bool(torch.isfinite(diameters).all() and (diameters > 0).all()):
        raise ValueError(f"{name} must be finite and positive, got {diameters.tolist()!r:.80}")
    return diameters


def physics_features(frames: Tensor, diameters: Tensor | Sequence[float] | None = None) -> Tensor:
    """Per-frame physics features ``(N, T, 4)`` in float64 (``(N, T, 6)`` with ``diameters``).

    With ``d_t = Σ_{s <= t} (OFF_s - ON_s)`` the running signed event total (the
    membrane's indentation, in events): ``d_t``, ``d_t²``, the OFF and ON totals of frame
    ``t`` and, given the bolt diameters ``D`` (N,), also ``d_t / D`` and ``d_t² / D``
    (under Hertz line contact the events see the product force × diameter).

    Args:
        frames: event counts ``(N, T, 2, H, W)``, any real dtype (channel 0 OFF, 1 ON).
        diameters: ``None`` or one bolt diameter per sequence (any positive unit).

    Example:
        >>> frames = torch.zeros(1, 3, 2, 2, 2)
        >>> frames[0, :, 0] = 1.0  # 4 OFF events per frame
        >>> physics_features(frames)[0].tolist()
        [[4.0, 16.0, 4.0, 0.0], [8.0, 64.0, 4.0, 0.0], [12.0, 144.0, 4.0, 0.0]]
        >>> physics_features(frames, [2.0])[0, -1, 4:].tolist()
        [6.0, 72.0]
    """
    frames = _check_frames(frames)
    totals = frames.detach().to("cpu", torch.float64).sum(dim=(-2, -1))  # (N, T, 2)
    running = totals.cumsum(dim=1)
    signed = (running[..., 0] - running[..., 1]).unsqueeze(-1)
    columns = [signed, signed.square(), totals]
    if diameters is not None:
        size = _check_diameters(diameters, frames.shape[0]).view(-1, 1, 1)
        columns += [signed / size, signed.square() / size]
    return torch.cat(columns, dim=-1)


class PhysicsLeastSquares(Baseline):
    """Least squares of force on the running signed event total, its square, the frame's
    totals and per-frame intercepts (the physics model of ``benchmarks/tactile/size_confound.py``).

    The model (features from :func:`physics_features`) is

    .. math::

        \\hat F_{n,t} = a_t + w_1 d_{n,t} + w_2 d_{n,t}^2 + w_3 \\mathrm{OFF}_{n,t}
        + w_4 \\mathrm{ON}_{n,t} \\;[+ w_5 d_{n,t} / D_n + w_6 d_{n,t}^2 / D_n]

    with ``d`` the running ``OFF - ON`` total and one intercept ``a_t`` per frame index:
    4 + T parameters (40 for 36 frames; 42 with the size terms), fitted in closed form in
    float64 (``torch.linalg.lstsq`` on the design with each feature column divided by its
    training root mean square, which changes the conditioning, not the solution). No
    penalty, no validation data: :meth:`fit` is the same with or without it.

    Events see force × diameter (Hertz line contact), so a model fitted on some bolt sizes
    extrapolates badly to others; ``size_aware=True`` adds the two size terms, and
    :meth:`fit` and :meth:`predict` then need the diameters (the bolt size as metadata).

    Args:
        size_aware: add the ``d / D`` and ``d² / D`` terms (needs ``diameters``).

    Example:
        >>> g = torch.Generator().manual_seed(0)
        >>> frames = torch.poisson(torch.full((8, 6, 2, 3, 3), 1.0), generator=g)
        >>> d = physics_features(frames)[..., 0]
        >>> force = 2.0 + 0.5 * d - 0.01 * d ** 2
        >>> model = PhysicsLeastSquares().fit(frames, force)
        >>> bool((model.predict(frames) - force).abs().max() < 1e-8), model.coef_.numel()
        (True, 10)
    """

    name = "physics least-squares"

    def __init__(self, size_aware: bool = False) -> None:
        if not isinstance(size_aware, bool):
            raise TypeError(f"size_aware must be a bool, got {size_aware!r}")
        self.size_aware = size_aware
        if size_aware:
            self.name = "physics least-squares + size"

    def _diameters(self, diameters: object, n: int) -> Tensor | None:
        if self.size_aware and diameters is None:
            raise ValueError("diameters: PhysicsLeastSquares(size_aware=True) needs the bolt diameters, got None")
        if not self.size_aware and diameters is not None:
            raise ValueError(
                "diameters: given to PhysicsLeastSquares(size_aware=False); pass size_aware=True to use them"
            )
        return None if diameters is None else _check_diameters(diameters, n)

    def _design(self, frames: Tensor, diameters: Tensor | None) -> Tensor:
        """``(N*T, K + T)`` design: scaled physics features, then one-hot frame index."""
        z = physics_features(frames, diameters) / self.feature_scale_
        n, steps, k = z.shape
        onehot = torch.eye(steps, dtype=torch.float64).expand(n, steps, steps)
        return torch.cat([z, onehot], dim=-1).reshape(n * steps, k + steps)

    def fit(
        self, frames: Tensor, force: Tensor, *, diameters: Tensor | Sequence[float] | None = None
    ) -> PhysicsLeastSquares:
        """Fit on ``frames`` ``(N, T, 2, H, W)``, ``force`` ``(N, T)`` (and ``diameters`` ``(N,)``)."""
        frames, force = _check_pair(frames, force)
        diameters = self._diameters(diameters, frames.shape[0])
        features = physics_features(frames, diameters).flatten(0, 1)
        rms = features.square().mean(dim=0).sqrt()
        self.feature_scale_ = torch.where(rms > 0, rms, torch.ones_like(rms))
        self._steps = frames.shape[1]
        design = self._design(frames, diameters)
        self.coef_ = torch.linalg.lstsq(design, force.reshape(-1, 1), driver="gelsd").solution[:, 0]
        return self

    def predict(self, frames: Tensor, *, diameters: Tensor | Sequence[float] | None = None) -> Tensor:
        """Predicted force ``(N, T)``, float64 on the CPU."""
        if self._steps is None:
            raise RuntimeError(f"{type(self).__name__}.predict called before fit")
        frames = _check_frames(frames)
        self._check_steps(frames)
        diameters = self._diameters(diameters, frames.shape[0])
        return (self._design(frames, diameters) @ self.coef_).reshape(frames.shape[:2])

    def __repr__(self) -> str:
        return f"PhysicsLeastSquares(size_aware={self.size_aware!r})"


def stack_items(data: object) -> tuple[Tensor, Tensor]:
    """``(frames, force)`` from a ``(frames, force)`` pair or a Dataset of ``(frames, force, ...)``.

    Example:
        >>> frames, force = stack_items([(torch.zeros(3, 2, 4, 4), torch.ones(3), {})] * 2)
        >>> tuple(frames.shape), tuple(force.shape)
        ((2, 3, 2, 4, 4), (2, 3))
    """
    if isinstance(data, (tuple, list)) and len(data) == 2 and all(isinstance(x, Tensor) for x in data):
        return data[0], data[1]
    try:
        n = len(data)  # type: ignore[arg-type]
    except TypeError:
        raise TypeError(
            f"data must be a (frames, force) pair or a Dataset of (frames, force, ...) items, "
            f"got {type(data).__name__}"
        ) from None
    items = [data[i] for i in range(n)]  # type: ignore[index]
    if not items:
        raise ValueError("data must hold at least one item, got an empty dataset")
    frames = torch.stack([torch.as_tensor(item[0]) for item in items])
    force = torch.stack([torch.as_tensor(item[1]) for item in items])
    return frames, force


def evaluate_baselines(
    train: object,
    val: object,
    test: object,
    *,
    baselines: Sequence[Baseline] | None = None,
) -> dict[str, dict[str, float]]:
    """Fit each baseline on ``train``; return its validation and test MSE (float64, N²).

    :class:`CumulativeCountRidge` with ``alpha=None`` picks its penalty on ``val``, so its
    ``val_mse`` is slightly optimistic; ``test_mse`` is clean for every baseline.

    Args:
        train: ``(frames, force)`` or a Dataset of ``(frames, force, meta)`` items.
        val: the same, for validation.
        test: the same, for test.
        baselines: the models to fit; default :class:`GlobalMean`, :class:`PerFrameMean`,
            :class:`CumulativeCountRidge` and :class:`PhysicsLeastSquares` (without the
            size terms: items' metadata are not read).

    Returns:
        ``{name: {"val_mse": float, "test_mse": float}}``.
    """
    splits = {}
    for name, data in (("train", train), ("val", val), ("test", test)):
        frames, force = stack_items(data)
        splits[name] = _check_pair(frames, force, name=f"{name} ")
    if baselines is None:
        baselines = (GlobalMean(), PerFrameMean(), CumulativeCountRidge(), PhysicsLeastSquares())
    scores: dict[str, dict[str, float]] = {}
    for model in baselines:
        if not isinstance(model, Baseline):
            raise TypeError(f"baselines must hold Baseline instances, got {type(model).__name__}")
        if getattr(model, "size_aware", False):
            raise ValueError(
                f"baselines: {model!r} needs bolt diameters, which evaluate_baselines does not read; "
                "fit it yourself with diameters="
            )
        if isinstance(model, CumulativeCountRidge):
            model.fit(*splits["train"], val=splits["val"])
        else:
            model.fit(*splits["train"])
        scores[model.name] = {
            f"{split}_mse": float((model.predict(splits[split][0]) - splits[split][1]).square().mean())
            for split in ("val", "test")
        }
    return scores
