"""The CMA-ES baseline of bench.protocol: a standard (mu/mu_w, lambda)-CMA-ES."""

import numpy as np
import pytest

from bench import cmaes

N = 15
# per-gene scales as different as the genome's (pixels ... distortion terms)
SCALES = np.logspace(-3, 3, N)
OPTIMUM = np.linspace(-1.0, 1.0, N) * SCALES


def ellipsoid(xs: np.ndarray) -> np.ndarray:
    """A rotated-free ellipsoid in scaled units, conditioned 1e4, maximum 0 at OPTIMUM."""
    return -np.sum(((xs - OPTIMUM) / SCALES) ** 2 * np.logspace(0, 4, N), axis=1)


def test_default_strategy_follows_the_tutorial():
    s = cmaes.default_strategy(N)
    assert (s.lam, s.mu) == (4 + int(3 * np.log(N)), (4 + int(3 * np.log(N))) // 2)
    assert s.weights.sum() == pytest.approx(1.0)
    assert np.all(np.diff(s.weights) < 0.0)
    assert 1.0 < s.mu_eff < s.mu
    assert 0.0 < s.c_1 + s.c_mu <= 1.0
    assert s.chi_n == pytest.approx(np.sqrt(N), rel=0.02)


def test_finds_the_optimum_of_a_badly_scaled_ellipsoid():
    # the step matches the scales: the scaled problem is a plain ellipsoid, which CMA-ES solves
    result = cmaes.maximise(ellipsoid, np.zeros(N), SCALES, 60_000, seed=1)
    assert result.stop_reason == "step_collapsed"
    assert result.evaluations < 60_000
    assert np.max(np.abs(result.genome - OPTIMUM) / SCALES) < 1e-6
    assert result.fitness == pytest.approx(float(ellipsoid(result.genome[None])[0]))


def test_finds_the_minimum_of_rosenbrock():
    # curved valley: needs the covariance (and its rank-one path) to adapt, not just sigma
    def rosenbrock(xs: np.ndarray) -> np.ndarray:
        return -np.sum(100.0 * (xs[:, 1:] - xs[:, :-1] ** 2) ** 2 + (1 - xs[:, :-1]) ** 2, axis=1)

    result = cmaes.maximise(rosenbrock, np.zeros(8), np.full(8, 0.5), 40_000, seed=0)
    assert np.allclose(result.genome, 1.0, atol=1e-5), result


def test_budget_is_whole_generations_and_never_exceeded():
    lam = cmaes.default_strategy(N).lam
    calls: list[int] = []

    def counted(xs: np.ndarray) -> np.ndarray:
        calls.append(len(xs))
        return ellipsoid(xs)

    result = cmaes.maximise(counted, np.zeros(N), SCALES, 10 * lam + 3, seed=0)
    assert result.stop_reason == "max_evaluations"
    assert calls == [lam] * 10
    assert (result.evaluations, result.generations) == (10 * lam, 10)


def test_first_generation_spreads_each_gene_by_its_step():
    seen: list[np.ndarray] = []

    def recorded(xs: np.ndarray) -> np.ndarray:
        seen.append(xs.copy())
        return ellipsoid(xs)

    start = OPTIMUM + SCALES
    cmaes.maximise(recorded, start, SCALES, 4000, seed=2, population_size=4000)
    first = seen[0]
    assert np.allclose(first.mean(axis=0), start, atol=0.1 * SCALES.max())
    assert np.allclose(first.std(axis=0) / SCALES, 1.0, atol=0.06)


def test_same_seed_same_run_and_failed_evaluations_rank_last():
    def with_failures(xs: np.ndarray) -> np.ndarray:
        values = ellipsoid(xs)
        values[xs[:, 0] > OPTIMUM[0] + 2 * SCALES[0]] = np.nan  # e.g. a camera that cannot project
        return values

    runs = [cmaes.maximise(with_failures, np.zeros(N), SCALES, 3000, seed=s) for s in (5, 5, 6)]
    assert np.array_equal(runs[0].genome, runs[1].genome)
    assert not np.array_equal(runs[0].genome, runs[2].genome)
    assert np.isfinite(runs[0].fitness)


def test_rejects_bad_input():
    with pytest.raises(ValueError):
        cmaes.maximise(ellipsoid, np.zeros(N), np.zeros(N), 1000)
    with pytest.raises(ValueError):
        cmaes.maximise(ellipsoid, np.zeros(N), SCALES[:3], 1000)
    with pytest.raises(ValueError):
        cmaes.maximise(ellipsoid, np.zeros(N), SCALES, 3)
    with pytest.raises(ValueError):
        cmaes.maximise(lambda xs: np.zeros(2), np.zeros(N), SCALES, 1000)
