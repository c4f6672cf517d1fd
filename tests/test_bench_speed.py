"""bench.speed's GA-inside-a-calibration row compares like with like: the replay of the
calibration's run_ga call repeats the very same run."""

import numpy as np

from app.calib.ga import DEFAULT_BUNDLE, run_ga
from bench import speed


def test_replayed_run_ga_repeats_the_calibrations_ga_run_exactly():
    image, start = speed.calibration_case()
    result, call = speed.calibrate_with_ga(image, start, seed=3, max_generations=25)
    assert result.bundle == DEFAULT_BUNDLE.name and result.generations == call.result.generations
    assert "progress" in call.kwargs  # the calibration reports progress; the replay drops it
    kwargs = {k: v for k, v in call.kwargs.items() if k != "progress"}
    replay = run_ga(*call.args, **kwargs)
    assert replay.generations == call.result.generations > 1
    assert np.array_equal(replay.genome, call.result.genome)
    assert np.array_equal(replay.best_history, call.result.best_history)
    assert np.array_equal(result.ga_genome, replay.genome)
    # the product's own per-generation figure is there to be compared
    assert result.timings_s["ga_per_generation_ms"] > 0.0
