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


def test_protocol_case_runs_every_method_from_the_same_start():
    from bench import protocol

    config = protocol.Config(
        bundles=(DEFAULT_BUNDLE.name,),
        best_bundle=DEFAULT_BUNDLE.name,
        methods=protocol.METHODS,
        baseline_evaluations=2000,
        max_generations=200,
        base_seed=0,
    )
    rows = protocol.run_case((protocol.Case("near", "none", 0), config))
    assert [r["method"] for r in rows] == ["ga", *protocol.METHODS]
    assert len({r["start_G_p"] for r in rows}) == 1 and rows[0]["start_G_p"] > 1.0
    by_method = {r["method"]: r for r in rows}
    # the product on a clean edge image from a near hint: the bar, with a margin
    assert by_method["product"]["G_p"] < 0.5, by_method["product"]
    assert by_method["product"]["verdict"] == "good"
    for method in ("cmaes", "subplex", "direct_l"):
        assert 0 < by_method[method]["evaluations"] <= 2000
        assert np.isfinite(by_method[method]["fitness"])
    # every baseline scores on the same map: the true camera's fitness is the same number
    assert len({r["target_fitness"] for r in rows if r["method"] != "ga"}) == 1


def test_sub_pixel_table_names_the_cells_below_target():
    from bench import protocol

    rows = []
    for d in synthetic.DISTANCES:
        for n in synthetic.NOISE_TYPES:
            for rep in range(10):
                miss = d == "far" and n == "grid" and rep < 2  # 80 %: below the far target
                refused = d == "near" and n == "salt" and rep == 0  # 90 %: below the near target
                g_p = np.inf if refused else (3.0 if miss else 0.2)
                rows.append(
                    {
                        "method": "product",
                        "distance": d,
                        "noise": n,
                        "G_p": g_p,
                        "fitness": np.nan if refused else 100.0,
                        "target_fitness": 101.0,
                        "elapsed_s": 1.0,
                    }
                )
    cells = protocol.sub_pixel_cells(rows, "product")
    assert cells[("far", "grid")] == (8, 10) and cells[("near", "all")] == (59, 60)
    assert sorted(protocol.missed_targets(cells)) == ["far/grid 8/10", "near/salt 9/10"]
    text = protocol.sub_pixel_report(rows, ["product"], DEFAULT_BUNDLE.name)
    assert "product: targets missed in" in text and "far/grid 8/10" in text
    # a product-only run prints no GA tables and no empty paper column
    config = protocol.Config((), DEFAULT_BUNDLE.name, ("product",), 1000, None, 0)
    whole = protocol.report(rows, config)
    assert "(a) Fig. 9" not in whole and "paper" not in whole.split("(e)")[0]
    assert "0.2 (29/30)" in whole  # (d): salt, the refused run is not under 10 px
