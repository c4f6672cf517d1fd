import subprocess
import sys
from math import comb
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from app.calib import camera, court, fitness, render, synthetic
from app.calib.ga import (
    BUNDLES,
    DEFAULT_BUNDLE,
    Bundle,
    GAResult,
    bundle_fitness_map,
    engine,
    get_bundle,
    run_ga,
)
from app.calib.ga import operators as ops

SIZE = (960, 540)
P1 = np.arange(15, dtype=np.float64)
P2 = 100.0 + np.arange(15, dtype=np.float64)


@pytest.fixture(scope="module")
def scene():
    """A clean synthetic edge image of the typical camera at 960x540, its maps and samples."""
    model = court.court_model()
    target = synthetic.typical_target_camera(SIZE)
    edges = render.rasterize_court(target, model, SIZE)
    samples = court.sample_edges(model, court.spacing_for_image(SIZE[0]))
    return target, edges, samples


def _children(strategy: int, p: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    c1, c2 = np.empty(15), np.empty(15)
    ops.crossover(P1, P2, strategy, p, rng, c1, c2)
    return c1, c2


@pytest.mark.parametrize(
    "strategy, p",
    [(ops.CROSS_SINGLE_POINT, 0.5), (ops.CROSS_TWO_POINT, 0.5), (ops.CROSS_UNIFORM, 0.5)],
)
def test_crossover_children_hold_each_parent_gene_once(strategy, p):
    rng = np.random.default_rng(0)
    for _ in range(500):
        c1, c2 = _children(strategy, p, rng)
        from1 = c1 == P1
        assert np.all(from1 | (c1 == P2))  # same position, one of the parents
        assert np.all(np.where(from1, c2 == P2, c2 == P1))  # child 2 got the other gene


def test_single_point_swaps_the_first_section_at_every_cut():
    rng = np.random.default_rng(1)
    cuts = []
    for _ in range(3000):
        c1, _ = _children(ops.CROSS_SINGLE_POINT, 0.5, rng)
        cut = int(np.argmax(c1 == P1))  # first gene kept from parent 1
        assert np.all(c1[:cut] == P2[:cut]) and np.all(c1[cut:] == P1[cut:])
        cuts.append(cut)
    counts = np.bincount(cuts, minlength=15)
    assert counts[0] == 0 and np.all(counts[1:] > 0)
    assert stats.chisquare(counts[1:]).pvalue > 1e-3


def test_two_point_swaps_a_middle_section_between_two_distinct_cuts():
    rng = np.random.default_rng(2)
    pairs = set()
    for _ in range(5000):
        c1, _ = _children(ops.CROSS_TWO_POINT, 0.5, rng)
        swapped = np.flatnonzero(c1 == P2)
        lo, hi = swapped[0], swapped[-1] + 1
        assert len(swapped) == hi - lo  # contiguous
        assert 1 <= lo < hi <= 14
        pairs.add((lo, hi))
    assert len(pairs) == comb(14, 2)  # every pair of distinct cuts in 1..14


@pytest.mark.parametrize("p", [0.5, 0.01])
def test_uniform_crossover_takes_genes_from_parent1_with_probability_p(p):
    rng = np.random.default_rng(3)
    draws = 4000
    from1 = sum(int((_children(ops.CROSS_UNIFORM, p, rng)[0] == P1).sum()) for _ in range(draws))
    n = draws * 15
    assert abs(from1 - n * p) < 5 * np.sqrt(n * p * (1 - p))


def _selection_counts(select, n: int, draws: int) -> np.ndarray:
    return np.bincount([select() for _ in range(draws)], minlength=n)


@pytest.mark.parametrize(
    "fit, weights",
    [
        ([1.0, 2.0, 3.0, 4.0], [1, 2, 3, 4]),  # non-negative: the fitness itself
        ([0.5, 0.5, 1.0], [1, 1, 2]),
        ([-3.0, -1.0, 0.0, 2.0], [0, 2, 3, 5]),  # negative (2F - 1 map): fitness - min
        ([-5.0, -5.0, -5.0], [1, 1, 1]),  # all equal: uniform
    ],
)
def test_roulette_picks_proportionally(fit, weights):
    rng = np.random.default_rng(4)
    fitness_arr = np.array(fit)
    draws = 20000
    counts = _selection_counts(lambda: ops.roulette_select(fitness_arr, rng), len(fit), draws)
    w = np.array(weights, dtype=float)
    expected = draws * w / w.sum()
    assert np.all(counts[w == 0] == 0)
    assert stats.chisquare(counts[w > 0], expected[w > 0]).pvalue > 1e-3


def _tournament_probabilities(n: int, k: int, p: float) -> np.ndarray:
    """P(genome of rank r wins): it is drawn with probability k / n; then its place a among the
    participants is hypergeometric and place a wins with p (1 - p)^a / (1 - (1 - p)^k)."""
    probs = np.zeros(n)
    norm = 1.0 - (1.0 - p) ** k
    for r in range(n):
        for a in range(k):
            place = comb(r, a) * comb(n - 1 - r, k - 1 - a) / comb(n - 1, k - 1)
            probs[r] += k / n * place * p * (1 - p) ** a / norm
    return probs


@pytest.mark.parametrize("n, k", [(8, 4), (16, 4), (16, 8), (8, 8)])
def test_tournament_probabilities(n, k):
    rng = np.random.default_rng(5)
    fit = rng.permutation(n).astype(float) - 3.0  # distinct, some negative
    rank = np.argsort(np.argsort(-fit))
    scratch = np.empty(n, dtype=np.int64)
    draws = 20000
    counts = _selection_counts(lambda: ops.tournament_select(fit, k, 0.5, rng, scratch), n, draws)
    by_rank = np.zeros(n)
    by_rank[rank] = counts
    expected = draws * _tournament_probabilities(n, k, 0.5)
    assert expected.sum() == pytest.approx(draws)
    assert stats.chisquare(by_rank, expected).pvalue > 1e-3


def _mutation_deltas(table: ops.MutationTable, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    out = np.zeros((n, 15))
    for i in range(n):
        ops.mutate(out[i], table.probability, table.kind, table.a, table.b, table.offset, rng)
    return out


@pytest.fixture(scope="module")
def uniform_deltas() -> np.ndarray:
    return _mutation_deltas(ops.UNIFORM_MUTATION, 40000, 6)


@pytest.fixture(scope="module")
def distribution_deltas() -> np.ndarray:
    return _mutation_deltas(ops.DISTRIBUTION_MUTATION, 40000, 7)


TABLE1_UNIFORM = [10, 10, 50, 50, 0.1, 0.15, 0.5, 0.05, 0.05, 0.05, 0.5, 0.5, 0.2, 0.1, 3.0]


@pytest.mark.parametrize("which", ["uniform", "distribution"])
def test_mutation_rates_match_table_1(which, uniform_deltas, distribution_deltas):
    deltas = uniform_deltas if which == "uniform" else distribution_deltas
    n = len(deltas)
    rates = np.array([0.05] * 10 + [0.01] * 5)
    changed = (deltas != 0.0).sum(axis=0)
    assert np.all(np.abs(changed - n * rates) < 5 * np.sqrt(n * rates * (1 - rates)))


def test_uniform_mutation_draws_match_table_1(uniform_deltas):
    for gene, half in enumerate(TABLE1_UNIFORM):
        d = uniform_deltas[:, gene]
        d = d[d != 0.0]
        assert np.all(np.abs(d) <= half)
        assert stats.kstest(d, stats.uniform(-half, 2 * half).cdf).pvalue > 1e-3, gene


def test_distribution_mutation_draws_match_table_1(distribution_deltas):
    expected = {
        camera.GENE["t_x"]: stats.norm(0, 0.1),
        camera.GENE["t_y"]: stats.norm(0, 0.2),
        camera.GENE["t_z"]: stats.lognorm(s=0.7, loc=-1.0),  # LN(0, 0.7) - 1
        camera.GENE["alpha"]: stats.norm(0, 0.05),
        camera.GENE["beta"]: stats.norm(0, 0.01),
        camera.GENE["gamma"]: stats.norm(0, 0.01),
    }
    for gene, half in enumerate(TABLE1_UNIFORM):
        expected.setdefault(gene, stats.uniform(-half, 2 * half))
    for gene, dist in expected.items():
        d = distribution_deltas[:, gene]
        d = d[d != 0.0]
        assert stats.kstest(d, dist.cdf).pvalue > 1e-3, gene
    t_z = distribution_deltas[:, camera.GENE["t_z"]]
    assert np.all(t_z[t_z != 0] > -1.0)  # the lognormal shift: skewed towards larger t_z


def test_initialisation_ranges():
    rng = np.random.default_rng(8)
    start = synthetic.typical_target_camera()
    pop = np.empty((4000, 15))
    ops.initialize_population(start, ops.INIT_LIMITS, rng, pop)
    limits = np.array([100, 100, 10, 10, 0.1, 0.1, 0.5] + [np.pi / 180] * 3 + [0] * 5)
    offsets = pop - start
    assert np.all(offsets[:, 10:] == 0.0)  # distortion shared with the start
    for gene in range(10):
        assert np.all(np.abs(offsets[:, gene]) <= limits[gene])
        cdf = stats.uniform(-limits[gene], 2 * limits[gene]).cdf
        assert stats.kstest(offsets[:, gene], cdf).pvalue > 1e-3


def test_bundles_are_the_96_of_table_2():
    assert len(BUNDLES) == 96
    assert len({b.name for b in BUNDLES.values()}) == 96
    assert len(set(BUNDLES.values())) == 96
    assert DEFAULT_BUNDLE.name == "n16-tdm-roulette-single-dist"
    assert (DEFAULT_BUNDLE.population_size, DEFAULT_BUNDLE.transformed_map) == (16, True)
    assert (DEFAULT_BUNDLE.selection, DEFAULT_BUNDLE.crossover) == ("roulette", "single")
    assert DEFAULT_BUNDLE.mutation == "dist"
    example = get_bundle("n8-dm-tournament4-uniform01-uniform")
    assert example.population_size == 8 and not example.transformed_map
    assert (example.selection, example.tournament_size, example.tournament_p) == (
        "tournament",
        4,
        0.5,
    )
    assert (example.crossover, example.uniform_p, example.mutation) == ("uniform", 0.01, "uniform")
    assert get_bundle("n16-tdm-tournament8-uniform50-dist").uniform_p == 0.5
    for name, bundle in BUNDLES.items():
        assert get_bundle(name) is bundle
    with pytest.raises(ValueError, match="n16-tdm-roulette-single-dist"):
        get_bundle("n16-best")
    with pytest.raises(ValueError):
        Bundle(population_size=1)


def test_bundle_fitness_map_follows_the_bundle(scene):
    _, edges, _ = scene
    dm = bundle_fitness_map(edges, get_bundle("n16-dm-roulette-single-dist"))
    tdm = bundle_fitness_map(edges, DEFAULT_BUNDLE)
    assert dm.min() == 0.0 and tdm.min() == -1.0
    assert np.abs(tdm - (2.0 * dm - 1.0)).max() <= 1e-6


def _near_start(target: np.ndarray) -> np.ndarray:
    start = target.copy()
    start[[0, 1, 2]] += [8.0, -8.0, 6.0]
    start[[4, 6, 7]] += [0.05, -0.08, 0.006]
    return start


def test_ga_improves_and_keeps_its_elites(scene):
    target, edges, samples = scene
    fmap = bundle_fitness_map(edges)
    start = _near_start(target)
    result = run_ga(fmap, samples, start, seed=1, stall_generations=100, max_generations=3000)
    assert isinstance(result, GAResult)
    history = result.best_history
    assert len(history) == result.generations
    assert np.all(np.diff(history) >= 0.0)  # elitism: the best never gets worse
    assert result.fitness == history[-1]
    # the reported fitness is exactly what population_fitness says about the genome
    assert result.fitness == fitness.population_fitness(result.genome, samples, fmap)[0]
    assert result.population.shape == (16, 15)
    assert np.all(np.diff(result.population_fitness) <= 0.0)
    assert np.array_equal(result.population[0], result.genome)
    # fitness values carried over (elites) or reused for exact copies are the true ones
    recomputed = fitness.population_fitness(result.population, samples, fmap)
    assert np.array_equal(result.population_fitness, recomputed)
    most = 16 + (result.generations - 1) * 14
    assert 16 < result.fitness_evaluations < most
    start_fitness = fitness.population_fitness(start, samples, fmap)[0]
    assert result.fitness > start_fitness
    error = synthetic.mean_reprojection_error(target, result.genome, court.floor_grid())
    assert error < 2.0


def test_termination_reasons(scene):
    target, _, samples = scene
    flat = np.zeros((SIZE[1], SIZE[0]), np.float32)  # fitness 0 for every genome: never improves
    stalled = run_ga(flat, samples, target, stall_generations=5)
    assert (stalled.stop_reason, stalled.generations) == ("stalled", 6)
    capped = run_ga(flat, samples, target, stall_generations=1000, max_generations=7)
    assert (capped.stop_reason, capped.generations, len(capped.best_history)) == (
        "max_generations",
        7,
        7,
    )
    only_initial = run_ga(flat, samples, target, max_generations=1)
    assert (only_initial.stop_reason, only_initial.generations) == ("max_generations", 1)
    calls: list[tuple[int, float]] = []
    timed = run_ga(
        flat,
        samples,
        target,
        stall_generations=10**9,
        max_generations=10**9,
        time_budget_s=0.3,
        progress=lambda generation, best: calls.append((generation, best)),
    )
    assert timed.stop_reason == "time_budget"
    assert 1 < timed.generations < 10**9
    assert calls and calls[-1] == (timed.generations, timed.fitness)
    assert len(calls) <= 3  # rate-limited to one call per 0.25 s, plus the final one
    assert all(isinstance(g, int) and isinstance(b, float) for g, b in calls)
    assert [g for g, _ in calls] == sorted(g for g, _ in calls)


def test_same_seed_same_result_bit_for_bit(scene):
    target, edges, samples = scene
    fmap = bundle_fitness_map(edges)
    start = _near_start(target)
    runs = [run_ga(fmap, samples, start, seed=s, max_generations=400) for s in (3, 3, 4)]
    assert np.array_equal(runs[0].genome, runs[1].genome)
    assert np.array_equal(runs[0].best_history, runs[1].best_history)
    assert np.array_equal(runs[0].population, runs[1].population)
    assert not np.array_equal(runs[0].genome, runs[2].genome)


@pytest.mark.parametrize(
    "name", ["n8-dm-tournament8-two-uniform", "n16-tdm-tournament4-uniform01-dist"]
)
def test_other_bundles_run(scene, name):
    target, edges, samples = scene
    bundle = get_bundle(name)
    fmap = bundle_fitness_map(edges, bundle)
    result = run_ga(fmap, samples, _near_start(target), bundle=bundle, max_generations=200)
    assert result.population.shape == (bundle.population_size, 15)
    assert np.all(np.diff(result.best_history) >= 0.0)


def test_odd_population_size_fills_exactly(scene):
    target, edges, samples = scene
    bundle = Bundle(population_size=5)
    assert bundle.name == "n5-tdm-roulette-single-dist"
    result = run_ga(bundle_fitness_map(edges), samples, target, bundle=bundle, max_generations=50)
    assert result.population.shape == (5, 15) and result.generations == 50


def test_run_ga_rejects_bad_input(scene):
    target, edges, samples = scene
    fmap = bundle_fitness_map(edges)
    with pytest.raises(ValueError):
        run_ga(fmap, samples, target[:14])
    bad = target.copy()
    bad[3] = np.nan
    with pytest.raises(ValueError):
        run_ga(fmap, samples, bad)
    with pytest.raises(ValueError):
        run_ga(fmap[None], samples, target)
    with pytest.raises(ValueError):
        run_ga(fmap, samples, target, stall_generations=0)
    with pytest.raises(ValueError):
        run_ga(fmap, samples, target, time_budget_s=0.0)


def test_a_run_loads_no_compiled_code_after_load_compiled_code(tmp_path):
    """In a fresh process, the first run reports the code load apart (code_load_s) and the run
    itself loads nothing more: every numba dispatcher it uses was loaded before its clock started.
    A dispatcher missing from the warm-up would compile or load inside elapsed_s and fail here."""
    script = tmp_path / "fresh.py"
    script.write_text(
        "import numba, numpy as np\n"
        "from app.calib import camera, court, fitness, synthetic\n"
        "from app.calib.ga import engine, operators, run_ga, bundle_fitness_map, get_bundle\n"
        "def loaded():\n"
        "    out = {}\n"
        "    for module in (camera, court, fitness, engine, operators):\n"
        "        for name, obj in vars(module).items():\n"
        "            if isinstance(obj, numba.core.registry.CPUDispatcher):\n"
        "                out[module.__name__ + '.' + name] = len(obj.signatures)\n"
        "    return out\n"
        "size = (480, 270)\n"
        "model = court.court_model()\n"
        "target = synthetic.typical_target_camera(size)\n"
        "edges = synthetic.render_edge_image(target, model, size)\n"
        "samples = court.sample_edges(model, court.spacing_for_image(size[0]))\n"
        "load_s = engine.load_compiled_code()\n"
        "before = loaded()\n"
        "again = engine.load_compiled_code()\n"
        "for name in ('n16-tdm-roulette-single-dist', 'n8-dm-tournament8-two-uniform'):\n"
        "    bundle = get_bundle(name)\n"
        "    result = run_ga(bundle_fitness_map(edges, bundle), samples, target, bundle=bundle,\n"
        "                    max_generations=40)\n"
        "    assert result.code_load_s == 0.0, result.code_load_s\n"
        "after = loaded()\n"
        "assert load_s > 0.0 and again == 0.0, (load_s, again)\n"
        "grew = {k: (before.get(k), v) for k, v in after.items() if v != before.get(k)}\n"
        "assert not grew, grew\n"
        "print('ok')\n"
    )
    root = Path(__file__).resolve().parents[1]
    done = subprocess.run(
        [sys.executable, str(script)], cwd=root, capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr[-2000:]


def test_code_load_is_reported_apart_once_loaded(scene):
    target, edges, samples = scene
    fmap = bundle_fitness_map(edges)
    run_ga(fmap, samples, target, max_generations=2)
    assert engine.load_compiled_code() == 0.0
    result = run_ga(fmap, samples, target, max_generations=20)
    assert result.code_load_s == 0.0 and result.elapsed_s > 0.0
