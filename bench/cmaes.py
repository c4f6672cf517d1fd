"""A standard (mu/mu_w, lambda)-CMA-ES (Hansen, "The CMA Evolution Strategy: A Tutorial", 2016),
maximising a batched objective; a baseline for `bench.protocol` beside the GA and NLopt.

The search runs in coordinates scaled per gene by `step`: x = start + step * y, with y starting at 0,
sigma = 1 and C = I, so the first generation spreads each gene by its own step (the protocol passes
Table 3's offsets: pixels, metres, radians and distortion terms differ by orders of magnitude).
Defaults of the tutorial throughout (population size, weights, learning rates, damping); no
restarts and no bounds.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

# Stop once the largest step the distribution can still take is this small relative to the
# initial one (scaled units): further generations only re-evaluate the same point.
TOL_STEP = 1e-12
# Stop when C's condition number passes this: its eigendecomposition is no longer trustworthy.
MAX_CONDITION = 1e14
STOP_REASONS = ("max_evaluations", "step_collapsed", "ill_conditioned")

BatchObjective = Callable[[np.ndarray], np.ndarray]  # (lam, n) -> (lam,) values to maximise


@dataclass(frozen=True)
class CMAResult:
    genome: np.ndarray  # (n,) best point evaluated
    fitness: float
    evaluations: int
    generations: int
    stop_reason: str  # one of STOP_REASONS
    final_step: np.ndarray  # (n,) sigma * sqrt(diag C) * step: the spread per gene at the end


@dataclass(frozen=True)
class Strategy:
    """The tutorial's default parameters for dimension n and population size lam."""

    lam: int
    mu: int
    weights: np.ndarray  # (mu,) positive, summing to 1
    mu_eff: float
    c_c: float
    c_sigma: float
    c_1: float
    c_mu: float
    d_sigma: float
    chi_n: float  # E||N(0, I)||


def default_strategy(n: int, lam: int | None = None) -> Strategy:
    if n < 1:
        raise ValueError(f"dimension must be at least 1, got {n}")
    lam = 4 + int(3 * np.log(n)) if lam is None else lam
    if lam < 2:
        raise ValueError(f"population size must be at least 2, got {lam}")
    mu = lam // 2
    raw = np.log(mu + 0.5) - np.log(np.arange(1, mu + 1))
    weights = raw / raw.sum()
    mu_eff = 1.0 / float(np.sum(weights**2))
    c_c = (4.0 + mu_eff / n) / (n + 4.0 + 2.0 * mu_eff / n)
    c_sigma = (mu_eff + 2.0) / (n + mu_eff + 5.0)
    c_1 = 2.0 / ((n + 1.3) ** 2 + mu_eff)
    c_mu = min(1.0 - c_1, 2.0 * (mu_eff - 2.0 + 1.0 / mu_eff) / ((n + 2.0) ** 2 + mu_eff))
    d_sigma = 1.0 + 2.0 * max(0.0, np.sqrt((mu_eff - 1.0) / (n + 1.0)) - 1.0) + c_sigma
    chi_n = np.sqrt(n) * (1.0 - 1.0 / (4.0 * n) + 1.0 / (21.0 * n * n))
    return Strategy(lam, mu, weights, mu_eff, c_c, c_sigma, c_1, c_mu, d_sigma, float(chi_n))


def maximise(
    objective: BatchObjective,
    start: np.ndarray,
    step: np.ndarray,
    max_evaluations: int,
    seed: int | np.random.Generator | None = 0,
    population_size: int | None = None,
) -> CMAResult:
    """Maximise `objective` from `start` (n,) with initial per-coordinate spread `step` (n,, > 0).

    Runs whole generations while they fit in `max_evaluations`; stops earlier if the step
    collapses or C becomes ill-conditioned. The best point ever evaluated is returned.
    """
    x0 = np.asarray(start, dtype=np.float64)
    scale = np.asarray(step, dtype=np.float64)
    if x0.ndim != 1 or scale.shape != x0.shape:
        raise ValueError(f"start and step must both be (n,), got {x0.shape} and {scale.shape}")
    if not (np.all(np.isfinite(x0)) and np.all(np.isfinite(scale)) and np.all(scale > 0)):
        raise ValueError("start must be finite and step finite and positive")
    n = x0.shape[0]
    s = default_strategy(n, population_size)
    if max_evaluations < s.lam:
        raise ValueError(
            f"max_evaluations must allow one generation ({s.lam}), got {max_evaluations}"
        )
    rng = np.random.default_rng(seed)

    mean = np.zeros(n)  # in scaled coordinates y; x = x0 + scale * y
    sigma = 1.0
    cov = np.eye(n)
    basis = np.eye(n)  # C = B diag(d^2) B^T
    d = np.ones(n)
    p_sigma = np.zeros(n)
    p_c = np.zeros(n)
    best_x, best_f = x0.copy(), -np.inf
    evaluations = generations = 0
    stop = "max_evaluations"
    while evaluations + s.lam <= max_evaluations:
        z = rng.standard_normal((s.lam, n))
        y = z * d @ basis.T  # rows ~ N(0, C)
        candidates = mean + sigma * y
        xs = x0 + scale * candidates
        values = np.asarray(objective(xs), dtype=np.float64)
        if values.shape != (s.lam,):
            raise ValueError(f"objective must return ({s.lam},), got {values.shape}")
        values = np.where(np.isfinite(values), values, -np.inf)  # a failed camera ranks last
        evaluations += s.lam
        generations += 1
        order = np.argsort(-values, kind="stable")
        if values[order[0]] > best_f:
            best_f, best_x = float(values[order[0]]), xs[order[0]].copy()

        chosen = y[order[: s.mu]]
        step_y = s.weights @ chosen  # (m_new - m) / sigma
        mean = mean + sigma * step_y
        # C^(-1/2) step_y = B diag(1/d) B^T step_y
        whitened = basis @ ((basis.T @ step_y) / d)
        p_sigma = (1.0 - s.c_sigma) * p_sigma + np.sqrt(
            s.c_sigma * (2.0 - s.c_sigma) * s.mu_eff
        ) * whitened
        norm_p_sigma = float(np.linalg.norm(p_sigma))
        # h_sigma stalls the update of p_c while p_sigma is long (sigma is still growing)
        threshold = (1.4 + 2.0 / (n + 1.0)) * s.chi_n
        h_sigma = norm_p_sigma / np.sqrt(1.0 - (1.0 - s.c_sigma) ** (2 * generations)) < threshold
        p_c = (1.0 - s.c_c) * p_c + h_sigma * np.sqrt(s.c_c * (2.0 - s.c_c) * s.mu_eff) * step_y
        rank_mu = (chosen * s.weights[:, None]).T @ chosen
        lost = (1.0 - h_sigma) * s.c_c * (2.0 - s.c_c)
        cov = (
            (1.0 - s.c_1 - s.c_mu) * cov
            + s.c_1 * (np.outer(p_c, p_c) + lost * cov)
            + s.c_mu * rank_mu
        )
        sigma *= float(np.exp((s.c_sigma / s.d_sigma) * (norm_p_sigma / s.chi_n - 1.0)))

        cov = np.triu(cov) + np.triu(cov, 1).T  # keep it exactly symmetric
        eigenvalues, basis = np.linalg.eigh(cov)
        if not np.all(np.isfinite(eigenvalues)) or eigenvalues.min() <= 0.0:
            stop = "ill_conditioned"
            break
        d = np.sqrt(eigenvalues)
        if eigenvalues.max() / eigenvalues.min() > MAX_CONDITION:
            stop = "ill_conditioned"
            break
        if sigma * d.max() < TOL_STEP:
            stop = "step_collapsed"
            break
    return CMAResult(
        genome=best_x,
        fitness=best_f,
        evaluations=evaluations,
        generations=generations,
        stop_reason=stop,
        final_step=sigma * np.sqrt(np.diag(cov)) * scale,
    )
