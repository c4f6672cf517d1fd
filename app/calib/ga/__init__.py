"""Genetic algorithm for camera calibration (paper section VI): engine, operators, bundles."""

from app.calib.ga.bundles import BUNDLES, DEFAULT_BUNDLE, Bundle, get_bundle
from app.calib.ga.engine import GAResult, bundle_fitness_map, run_ga

__all__ = [
    "BUNDLES",
    "DEFAULT_BUNDLE",
    "Bundle",
    "GAResult",
    "bundle_fitness_map",
    "get_bundle",
    "run_ga",
]
