"""Strategy bundles (paper section VII, Table 2): one strategy per GA operator, selectable by name.

2 population sizes x 2 fitness maps x 3 selections x 4 crossovers x 2 mutations = 96 bundles,
named like `n16-tdm-roulette-single-dist`:
  n8 | n16                                      initialisation, population size N
  dm | tdm                                      distance map F | transformed map 2F - 1
  roulette | tournament4 | tournament8          selection (tournaments with p = 0.5)
  single | two | uniform50 | uniform01          crossover (uniform with p = 0.5 | 0.01, in percent)
  uniform | dist                                mutation strategy of Table 1
Termination (no improvement for n = 300 generations) is the same for all and lives in the engine.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

from app.calib.ga import operators as ops

_SELECTIONS = ("roulette", "tournament")
_CROSSOVERS = ("single", "two", "uniform")
_MUTATIONS = ("uniform", "dist")


@dataclass(frozen=True)
class Bundle:
    """One combination of strategies. Any population size >= 2 is allowed (the paper's are 8, 16)."""

    population_size: int = 16
    transformed_map: bool = True
    selection: str = "roulette"
    tournament_size: int = 4
    tournament_p: float = 0.5
    crossover: str = "single"
    uniform_p: float = 0.5
    mutation: str = "dist"

    def __post_init__(self) -> None:
        if self.population_size < 2:
            raise ValueError("population_size must be at least 2 (two elites are carried over)")
        if self.selection not in _SELECTIONS:
            raise ValueError(f"selection must be one of {_SELECTIONS}, got {self.selection!r}")
        if self.crossover not in _CROSSOVERS:
            raise ValueError(f"crossover must be one of {_CROSSOVERS}, got {self.crossover!r}")
        if self.mutation not in _MUTATIONS:
            raise ValueError(f"mutation must be one of {_MUTATIONS}, got {self.mutation!r}")
        if self.tournament_size < 1 or not 0.0 < self.tournament_p <= 1.0:
            raise ValueError("tournament needs size >= 1 and 0 < p <= 1")
        if not 0.0 <= self.uniform_p <= 1.0:
            raise ValueError("uniform crossover probability must be in [0, 1]")

    @property
    def name(self) -> str:
        selection = (
            "roulette" if self.selection == "roulette" else f"tournament{self.tournament_size}"
        )
        crossover = (
            f"uniform{round(self.uniform_p * 100):02d}"
            if self.crossover == "uniform"
            else self.crossover
        )
        fitness = "tdm" if self.transformed_map else "dm"
        return f"n{self.population_size}-{fitness}-{selection}-{crossover}-{self.mutation}"

    @property
    def selection_code(self) -> int:
        return ops.SELECT_ROULETTE if self.selection == "roulette" else ops.SELECT_TOURNAMENT

    @property
    def crossover_code(self) -> int:
        return {
            "single": ops.CROSS_SINGLE_POINT,
            "two": ops.CROSS_TWO_POINT,
            "uniform": ops.CROSS_UNIFORM,
        }[self.crossover]

    @property
    def mutation_table(self) -> ops.MutationTable:
        return ops.UNIFORM_MUTATION if self.mutation == "uniform" else ops.DISTRIBUTION_MUTATION


def _all_bundles() -> dict[str, Bundle]:
    bundles = []
    selections = (("roulette", 4), ("tournament", 4), ("tournament", 8))
    crossovers = (("single", 0.5), ("two", 0.5), ("uniform", 0.5), ("uniform", 0.01))
    for n, transformed, (sel, k), (cross, p), mut in itertools.product(
        (8, 16), (False, True), selections, crossovers, _MUTATIONS
    ):
        bundles.append(
            Bundle(
                population_size=n,
                transformed_map=transformed,
                selection=sel,
                tournament_size=k,
                crossover=cross,
                uniform_p=p,
                mutation=mut,
            )
        )
    return {b.name: b for b in bundles}


BUNDLES: dict[str, Bundle] = _all_bundles()
# VII-A3: N = 16, transformed distance map, roulette wheel, single point, distribution mutation
DEFAULT_BUNDLE: Bundle = BUNDLES["n16-tdm-roulette-single-dist"]


def get_bundle(name: str) -> Bundle:
    try:
        return BUNDLES[name]
    except KeyError:
        raise ValueError(
            f"unknown bundle {name!r}; names look like {DEFAULT_BUNDLE.name!r} "
            "(n8|n16)-(dm|tdm)-(roulette|tournament4|tournament8)-"
            "(single|two|uniform50|uniform01)-(uniform|dist)"
        ) from None
