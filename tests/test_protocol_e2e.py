"""A short end-to-end calibration of the paper's protocol: near start, noiseless edge image, 1080p."""

import numpy as np

from app.calib import court, synthetic
from app.calib.ga import DEFAULT_BUNDLE, bundle_fitness_map, run_ga

SIZE = (1920, 1080)
# Seed 1's near start is a typical one: its G_p MRE (15.9 px) sits at the median of near starts
# (14.6 px over 500 seeds); it was chosen for that before the GA was run on it.
START_SEED = 1


def test_near_start_calibrates_under_2px_on_the_floor_grid():
    model = court.court_model()
    target = synthetic.typical_target_camera(SIZE)
    start = synthetic.wiggle_camera(target, "near", START_SEED)
    start_mre = synthetic.protocol_errors(target, start, model)["G_p"]
    assert start_mre > 10.0  # a real offset, not a start that already fits

    edges = synthetic.render_edge_image(target, model, SIZE)
    fmap = bundle_fitness_map(edges, DEFAULT_BUNDLE)
    samples = court.sample_edges(model, court.spacing_for_image(SIZE[0]))
    result = run_ga(fmap, samples, start, bundle=DEFAULT_BUNDLE, seed=0)

    errors = synthetic.protocol_errors(target, result.genome, model)
    assert errors["G_p"] < 2.0, (start_mre, errors, result.generations, result.stop_reason)
    assert np.all(np.isfinite(result.genome))
