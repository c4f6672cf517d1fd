"""GA operators of paper sections VI-A, VI-C, VI-D and VI-E as small compiled functions.

Every operator takes the `np.random.Generator` explicitly, so a seed fixes the whole run, and writes
into arrays the caller owns (the compiled generation loop reuses its buffers; tests call these
functions directly from Python). Strategies are integer codes so the compiled loop can switch on them.
"""

from __future__ import annotations

import numba
import numpy as np

from app.calib.camera import N_GENES

# Selection strategies (VI-C)
SELECT_ROULETTE = 0
SELECT_TOURNAMENT = 1
# Crossover strategies (VI-D)
CROSS_SINGLE_POINT = 0
CROSS_TWO_POINT = 1
CROSS_UNIFORM = 2
# Per-gene mutation draw kinds (Table 1)
DRAW_UNIFORM = 0  # U(a, b)
DRAW_NORMAL = 1  # N(a, b): mean a, standard deviation b
DRAW_LOGNORMAL = 2  # LN(a, b): exp of N(a, b)

# VI-A: uniform offsets around the start genome; distortion genes are shared (limit 0).
INIT_LIMITS = np.array([100.0, 100.0, 10.0, 10.0, 0.1, 0.1, 0.5] + [np.pi / 180.0] * 3 + [0.0] * 5)


class MutationTable:
    """Table 1 as arrays over the 15 genes: probability, draw kind, two parameters, offset."""

    def __init__(
        self,
        probability: np.ndarray,
        kind: np.ndarray,
        a: np.ndarray,
        b: np.ndarray,
        offset: np.ndarray,
    ) -> None:
        self.probability = np.ascontiguousarray(probability, dtype=np.float64)
        self.kind = np.ascontiguousarray(kind, dtype=np.int64)
        self.a = np.ascontiguousarray(a, dtype=np.float64)
        self.b = np.ascontiguousarray(b, dtype=np.float64)
        self.offset = np.ascontiguousarray(offset, dtype=np.float64)
        for arr in (self.probability, self.kind, self.a, self.b, self.offset):
            if arr.shape != (N_GENES,):
                raise ValueError("mutation table rows must have 15 entries")


_P_MUT = np.array([0.05] * 10 + [0.01] * 5)
# symmetric uniform half-widths of Table 1's uniform strategy
_UNIFORM_HALF = np.array(
    [10.0, 10.0, 50.0, 50.0, 0.1, 0.15, 0.5, 0.05, 0.05, 0.05, 0.5, 0.5, 0.2, 0.1, 3.0]
)


def _uniform_table() -> MutationTable:
    return MutationTable(
        _P_MUT, np.full(N_GENES, DRAW_UNIFORM), -_UNIFORM_HALF, _UNIFORM_HALF, np.zeros(N_GENES)
    )


def _distribution_table() -> MutationTable:
    kind = np.full(N_GENES, DRAW_UNIFORM)
    a = -_UNIFORM_HALF.copy()
    b = _UNIFORM_HALF.copy()
    offset = np.zeros(N_GENES)
    # t_x, t_y, alpha, beta, gamma: N(0, sigma); t_z: LN(0, 0.7) - 1 (skewed towards larger t_z)
    for gene, sigma in ((4, 0.1), (5, 0.2), (7, 0.05), (8, 0.01), (9, 0.01)):
        kind[gene], a[gene], b[gene] = DRAW_NORMAL, 0.0, sigma
    kind[6], a[6], b[6], offset[6] = DRAW_LOGNORMAL, 0.0, 0.7, -1.0
    return MutationTable(_P_MUT, kind, a, b, offset)


UNIFORM_MUTATION = _uniform_table()
DISTRIBUTION_MUTATION = _distribution_table()


@numba.njit(cache=True)
def initialize_population(
    start: np.ndarray, limits: np.ndarray, rng: np.random.Generator, out: np.ndarray
) -> None:
    """VI-A: out[i, j] = start[j] + U(-limits[j], limits[j]) (genes with limit 0 copy the start)."""
    for i in range(out.shape[0]):
        for j in range(out.shape[1]):
            if limits[j] > 0.0:
                out[i, j] = start[j] + rng.uniform(-limits[j], limits[j])
            else:
                out[i, j] = start[j]


@numba.njit(cache=True)
def roulette_select(fitness: np.ndarray, rng: np.random.Generator) -> int:
    """VI-C1: index drawn with probability proportional to its weight.

    Weights are the fitness itself when no fitness is negative (the paper's rule, always the case
    for the F map); otherwise fitness - min, so that the 2F - 1 map's negative sums still rank by
    fitness (the worst genome then gets weight 0). All-zero weights mean a uniform draw.
    """
    n = fitness.shape[0]
    low = 0.0
    for i in range(n):
        if fitness[i] < low:
            low = fitness[i]
    total = 0.0
    for i in range(n):
        total += fitness[i] - low
    if not total > 0.0:
        return int(rng.integers(0, n))
    target = rng.random() * total
    acc = 0.0
    for i in range(n):
        acc += fitness[i] - low
        if target < acc:
            return i
    # rounding can leave target == acc at the very end: take the last genome with weight
    for i in range(n - 1, -1, -1):
        if fitness[i] - low > 0.0:
            return i
    return n - 1


@numba.njit(cache=True)
def tournament_select(
    fitness: np.ndarray, k: int, p: float, rng: np.random.Generator, scratch: np.ndarray
) -> int:
    """VI-C2: k distinct participants drawn uniformly, ranked by fitness (descending, ties by index);
    the a-th (from 0) wins with probability p (1 - p)^a, renormalised over the k participants.

    `scratch` is an int64 buffer of at least len(fitness) entries.
    """
    n = fitness.shape[0]
    k = min(k, n)
    for i in range(n):
        scratch[i] = i
    # partial Fisher-Yates: the first k entries become a uniform k-subset
    for i in range(k):
        j = i + rng.integers(0, n - i)
        tmp = scratch[i]
        scratch[i] = scratch[j]
        scratch[j] = tmp
    # insertion sort of the k participants by fitness descending, index ascending on ties
    for i in range(1, k):
        item = scratch[i]
        j = i - 1
        while j >= 0 and (
            fitness[scratch[j]] < fitness[item]
            or (fitness[scratch[j]] == fitness[item] and scratch[j] > item)
        ):
            scratch[j + 1] = scratch[j]
            j -= 1
        scratch[j + 1] = item
    total = 1.0 - (1.0 - p) ** k  # sum of p (1 - p)^a for a < k
    target = rng.random() * total
    weight = p
    acc = 0.0
    for a in range(k):
        acc += weight
        if target < acc:
            return scratch[a]
        weight *= 1.0 - p
    return scratch[k - 1]


@numba.njit(cache=True)
def crossover(
    parent1: np.ndarray,
    parent2: np.ndarray,
    strategy: int,
    uniform_p: float,
    rng: np.random.Generator,
    child1: np.ndarray,
    child2: np.ndarray,
) -> None:
    """VI-D: two children from two parents.

    Single point: one cut c in 1..14, the first sections [0, c) are swapped. Two point: two distinct
    cuts, the middle section is swapped. Uniform: child 1 takes each gene from parent 1 with
    probability `uniform_p` (else from parent 2); child 2 gets the other parent's gene.
    """
    n = parent1.shape[0]
    if strategy == CROSS_UNIFORM:
        for j in range(n):
            if rng.random() < uniform_p:
                child1[j] = parent1[j]
                child2[j] = parent2[j]
            else:
                child1[j] = parent2[j]
                child2[j] = parent1[j]
        return
    if strategy == CROSS_SINGLE_POINT:
        lo = 0
        hi = rng.integers(1, n)
    else:
        a = rng.integers(1, n)
        b = rng.integers(1, n - 1)
        if b >= a:
            b += 1  # b uniform over the cuts other than a
        lo = min(a, b)
        hi = max(a, b)
    for j in range(n):
        if lo <= j < hi:
            child1[j] = parent2[j]
            child2[j] = parent1[j]
        else:
            child1[j] = parent1[j]
            child2[j] = parent2[j]


@numba.njit(cache=True)
def mutate(
    genome: np.ndarray,
    probability: np.ndarray,
    kind: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    offset: np.ndarray,
    rng: np.random.Generator,
) -> None:
    """VI-E, in place: each gene j, with probability probability[j], gets a Table 1 draw added."""
    for j in range(genome.shape[0]):
        if rng.random() < probability[j]:
            if kind[j] == DRAW_UNIFORM:
                draw = rng.uniform(a[j], b[j])
            elif kind[j] == DRAW_NORMAL:
                draw = rng.normal(a[j], b[j])
            else:
                draw = rng.lognormal(a[j], b[j])
            genome[j] += draw + offset[j]
