"""The genetic algorithm of paper Algorithm 1, compiled end to end.

Python sets up the run and calls the compiled `_evolve` for chunks of generations (~0.1 s each), so
that the time budget and the progress callback are handled between chunks while each generation
(selection, crossover, mutation, fitness of the new genomes) runs without touching Python. The
whole run draws from one `np.random.Generator` seeded by `seed`, so a seed fixes the result bit for
bit; chunk boundaries do not change the sequence of draws.

The first run in a process also loads the compiled code from numba's on-disk cache (or compiles
it): `load_compiled_code` does that on a tiny problem before the run's clock starts, and the
run reports it apart (`GAResult.code_load_s`), so `elapsed_s` is what every run costs.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass

import numba
import numpy as np

from app.calib import fitness as fit
from app.calib.camera import N_GENES
from app.calib.court import LineSamples
from app.calib.ga import operators as ops
from app.calib.ga.bundles import DEFAULT_BUNDLE, Bundle

DEFAULT_STALL_GENERATIONS = 300  # VI-F: n = 300
DEFAULT_MAX_GENERATIONS = 50_000
STOP_REASONS = ("stalled", "max_generations", "time_budget")

_RUNNING = -1
_STALLED = 0
_MAX_GENERATIONS = 1
_CHUNK_SECONDS = 0.1  # compiled work between two returns to Python
_PROGRESS_INTERVAL_S = 0.25  # at most ~4 progress calls per second

ProgressFn = Callable[[int, float], None]


@dataclass(frozen=True)
class GAResult:
    """Outcome of one GA run. `best_history[g]` is the best fitness after generation g + 1 and
    `mean_history[g]` that generation's mean fitness (the convergence plot)."""

    genome: np.ndarray  # (15,) the best genome of the last generation (= best ever: elitism)
    fitness: float
    generations: int  # generations evaluated, the initial population included
    stop_reason: str  # one of STOP_REASONS
    elapsed_s: float
    best_history: np.ndarray  # (generations,)
    mean_history: np.ndarray  # (generations,)
    population: np.ndarray  # (N, 15) last generation, best first
    population_fitness: np.ndarray  # (N,)
    fitness_evaluations: int  # computed; elites and exact copies of known genomes are not
    code_load_s: float = 0.0  # once per process: loading the compiled code (not in elapsed_s)


def bundle_fitness_map(edge_image: np.ndarray, bundle: Bundle = DEFAULT_BUNDLE) -> np.ndarray:
    """The lookup map a bundle uses: F (distance map strategy) or 2F - 1 (transformed)."""
    return fit.fitness_map(edge_image, transformed=bundle.transformed_map)


@numba.njit(cache=True)
def _sort_descending(fitness: np.ndarray, order: np.ndarray) -> None:
    """Indices by fitness descending, ties by index (insertion sort: N is 8..32)."""
    n = fitness.shape[0]
    for i in range(n):
        order[i] = i
    for i in range(1, n):
        item = order[i]
        j = i - 1
        while j >= 0 and fitness[order[j]] < fitness[item]:
            order[j + 1] = order[j]
            j -= 1
        order[j + 1] = item


@numba.njit(cache=True, inline="always")
def _same_genome(a: np.ndarray, b: np.ndarray) -> bool:
    # an explicit loop: numba compiles it to an early-exit compare, not a generator
    for j in range(a.shape[0]):  # noqa: SIM110
        if a[j] != b[j]:
            return False
    return True


@numba.njit(cache=True)
def _reuse_known_fitness(
    c: int, next_pop: np.ndarray, next_fitness: np.ndarray, pop: np.ndarray, fitness: np.ndarray
) -> bool:
    """If child c is an exact copy of a genome whose fitness is known (current generation, or an
    earlier row of the next one), copy that fitness and return True.

    Once the population converges, a third to a half of all children are such copies (same
    parent twice, cuts between equal genes, no mutation). The fitness is a pure function of the
    genome, so reusing it changes nothing in the run, bit for bit.
    """
    child = next_pop[c]
    for k in range(pop.shape[0]):
        if _same_genome(pop[k], child):
            next_fitness[c] = fitness[k]
            return True
    for k in range(c):
        if _same_genome(next_pop[k], child):
            next_fitness[c] = next_fitness[k]
            return True
    return False


@numba.njit(cache=True)
def _select(
    fitness: np.ndarray,
    selection: int,
    k: int,
    p: float,
    rng: np.random.Generator,
    scratch: np.ndarray,
) -> int:
    if selection == ops.SELECT_ROULETTE:
        return ops.roulette_select(fitness, rng)
    return ops.tournament_select(fitness, k, p, rng, scratch)


@numba.njit(cache=True)
def _evolve(
    pop: np.ndarray,
    fitness: np.ndarray,
    rng: np.random.Generator,
    selection: int,
    tournament_size: int,
    tournament_p: float,
    crossover: int,
    uniform_p: float,
    mut_probability: np.ndarray,
    mut_kind: np.ndarray,
    mut_a: np.ndarray,
    mut_b: np.ndarray,
    mut_offset: np.ndarray,
    xyz: np.ndarray,
    joins_next: np.ndarray,
    fmap: np.ndarray,
    ws: fit.Workspace,
    counters: np.ndarray,
    best: np.ndarray,
    stall_generations: int,
    max_generations: int,
    n_steps: int,
    history: np.ndarray,
    mean_history: np.ndarray,
) -> tuple[int, int]:
    """Run up to `n_steps` generations of Algorithm 1 on (pop, fitness), updated in place.

    counters = [generations evaluated, generation of the last strict improvement, fitness
    evaluations computed]; best = [best fitness]. history and mean_history receive the best and the
    mean fitness after each new generation. Returns (steps done, stop code).
    """
    n = pop.shape[0]
    next_pop = np.empty_like(pop)
    next_fitness = np.empty_like(fitness)
    order = np.empty(n, dtype=np.int64)
    scratch = np.empty(n, dtype=np.int64)
    spare = np.empty(pop.shape[1])
    for step in range(n_steps):
        # lines 5-6: sort, carry the two best over (their fitness is known: not recomputed)
        _sort_descending(fitness, order)
        for e in range(2):
            next_pop[e] = pop[order[e]]
            next_fitness[e] = fitness[order[e]]
        # lines 7-12: pairs of parents -> two mutated children, until N genomes
        i = 2
        while i < n:
            a = _select(fitness, selection, tournament_size, tournament_p, rng, scratch)
            b = _select(fitness, selection, tournament_size, tournament_p, rng, scratch)
            second = next_pop[i + 1] if i + 1 < n else spare
            ops.crossover(pop[a], pop[b], crossover, uniform_p, rng, next_pop[i], second)
            ops.mutate(next_pop[i], mut_probability, mut_kind, mut_a, mut_b, mut_offset, rng)
            ops.mutate(second, mut_probability, mut_kind, mut_a, mut_b, mut_offset, rng)
            i += 2
        for c in range(2, n):
            if not _reuse_known_fitness(c, next_pop, next_fitness, pop, fitness):
                next_fitness[c] = fit.genome_fitness_njit(next_pop[c], xyz, joins_next, fmap, ws)
                counters[2] += 1
        # line 13
        pop[:] = next_pop
        fitness[:] = next_fitness
        counters[0] += 1
        generation_best = fitness.max()
        if generation_best > best[0]:
            best[0] = generation_best
            counters[1] = counters[0]
        history[step] = best[0]
        mean_history[step] = fitness.mean()
        # line 14 (VI-F)
        if counters[0] - counters[1] >= stall_generations:
            return step + 1, _STALLED
        if counters[0] >= max_generations:
            return step + 1, _MAX_GENERATIONS
    return n_steps, _RUNNING


def _check_inputs(
    fitness_map: np.ndarray,
    start_genome: np.ndarray,
    stall_generations: int,
    max_generations: int,
    time_budget_s: float | None,
) -> tuple[np.ndarray, np.ndarray]:
    fmap = fit.check_fitness_map(fitness_map)
    start = np.asarray(start_genome, dtype=np.float64)
    if start.shape != (N_GENES,) or not np.all(np.isfinite(start)):
        raise ValueError("start genome must be 15 finite numbers")
    if stall_generations < 1 or max_generations < 1:
        raise ValueError("stall_generations and max_generations must be at least 1")
    if time_budget_s is not None and not time_budget_s > 0:
        raise ValueError("time_budget_s must be positive (or None)")
    return fmap, np.ascontiguousarray(start)


def load_compiled_code() -> float:
    """Load the GA's compiled functions into this process (from numba's cache, or compile them)
    by running two generations on a tiny problem; seconds spent, 0.0 if they were loaded."""
    if all(f.signatures for f in _COMPILED):
        return 0.0
    began = time.perf_counter()
    tiny_map = np.zeros((2, 2), dtype=np.float32)
    tiny_samples = LineSamples(np.zeros((2, 3)), np.array([0, 2], dtype=np.int64))
    _run(tiny_map, tiny_samples, np.ones(N_GENES), DEFAULT_BUNDLE, 0, 1, 2, None, None)
    return time.perf_counter() - began


def run_ga(
    fitness_map: np.ndarray,
    samples: LineSamples,
    start_genome: np.ndarray,
    bundle: Bundle = DEFAULT_BUNDLE,
    seed: int = 0,
    stall_generations: int = DEFAULT_STALL_GENERATIONS,
    max_generations: int = DEFAULT_MAX_GENERATIONS,
    time_budget_s: float | None = None,
    progress: ProgressFn | None = None,
) -> GAResult:
    """Algorithm 1 from `start_genome` on a fitness map (from `bundle_fitness_map`).

    Stops when the best fitness has not strictly improved for `stall_generations` generations
    ("stalled"), after `max_generations` generations ("max_generations"), or once `time_budget_s`
    has passed ("time_budget", checked every ~0.1 s). `progress(generation, best_fitness)` is called
    at most a few times per second. The first call in a process loads the compiled code first
    (`code_load_s`); the time budget and `elapsed_s` start after it.
    """
    fmap, start = _check_inputs(
        fitness_map, start_genome, stall_generations, max_generations, time_budget_s
    )
    code_load_s = load_compiled_code()
    result = _run(
        fmap,
        samples,
        start,
        bundle,
        seed,
        stall_generations,
        max_generations,
        time_budget_s,
        progress,
    )
    return dataclasses.replace(result, code_load_s=code_load_s)


def _run(
    fmap: np.ndarray,
    samples: LineSamples,
    start: np.ndarray,
    bundle: Bundle,
    seed: int,
    stall_generations: int,
    max_generations: int,
    time_budget_s: float | None,
    progress: ProgressFn | None,
) -> GAResult:
    """run_ga on checked inputs (fmap C-contiguous float32, start (15,) float64)."""
    started = time.perf_counter()
    arrays = fit.sample_arrays(samples)
    ws = fit.make_workspace(arrays.xyz.shape[1])
    rng = np.random.default_rng(seed)
    n = bundle.population_size
    table = bundle.mutation_table

    pop = np.empty((n, N_GENES))
    ops.initialize_population(start, ops.INIT_LIMITS, rng, pop)
    fitness = np.empty(n)
    fit.population_fitness_njit(pop, arrays.xyz, arrays.joins_next, fmap, ws, fitness, 0)
    counters = np.array([1, 1, n], dtype=np.int64)
    best = np.array([fitness.max()])
    histories = [best.copy()]
    means = [np.array([fitness.mean()])]

    stop = _RUNNING
    if max_generations <= 1:
        stop = _MAX_GENERATIONS
    chunk = 32
    last_progress = started
    while stop == _RUNNING:
        steps = min(chunk, max_generations - int(counters[0]))
        history = np.empty(steps)
        mean_history = np.empty(steps)
        chunk_started = time.perf_counter()
        done, stop = _evolve(
            pop,
            fitness,
            rng,
            bundle.selection_code,
            bundle.tournament_size,
            bundle.tournament_p,
            bundle.crossover_code,
            bundle.uniform_p,
            table.probability,
            table.kind,
            table.a,
            table.b,
            table.offset,
            arrays.xyz,
            arrays.joins_next,
            fmap,
            ws,
            counters,
            best,
            stall_generations,
            max_generations,
            steps,
            history,
            mean_history,
        )
        histories.append(history[:done])
        means.append(mean_history[:done])
        now = time.perf_counter()
        if stop != _RUNNING:
            break
        if time_budget_s is not None and now - started >= time_budget_s:
            break
        per_generation_s = max((now - chunk_started) / max(done, 1), 1e-7)
        chunk = int(np.clip(_CHUNK_SECONDS / per_generation_s, 1, 1_000_000))
        if time_budget_s is not None:
            remaining = time_budget_s - (now - started)
            chunk = max(1, min(chunk, int(remaining / per_generation_s) + 1))
        if progress is not None and now - last_progress >= _PROGRESS_INTERVAL_S:
            progress(int(counters[0]), float(best[0]))
            last_progress = now

    reason = {_STALLED: "stalled", _MAX_GENERATIONS: "max_generations", _RUNNING: "time_budget"}
    order = np.argsort(-fitness, kind="stable")
    best_history = np.concatenate(histories)
    if progress is not None:
        progress(int(counters[0]), float(best[0]))
    return GAResult(
        genome=pop[order[0]].copy(),
        fitness=float(fitness[order[0]]),
        generations=int(counters[0]),
        stop_reason=reason[stop],
        elapsed_s=time.perf_counter() - started,
        best_history=best_history,
        mean_history=np.concatenate(means),
        population=pop[order].copy(),
        population_fitness=fitness[order].copy(),
        fitness_evaluations=int(counters[2]),
    )


# every compiled function a run calls from Python (the rest are compiled into these)
_COMPILED = (fit.make_workspace, fit.population_fitness_njit, ops.initialize_population, _evolve)
