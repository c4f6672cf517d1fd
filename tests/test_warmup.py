"""The warm-ups cover real work: after them, a calibration of a rendered clip and /project's
projection compile no kernel for new argument types."""

from __future__ import annotations

import numpy as np
import pytest

from app.calib import camera, pipeline, scene, synthetic, warmup
from app.calib.background import background_from_frames


@pytest.mark.slow
def test_a_job_after_the_warm_ups_compiles_nothing_new() -> None:
    warmup.warm_up(warmup.API_PARTS + warmup.WORKER_PARTS)
    size = (480, 270)
    genome = synthetic.typical_target_camera(size)
    frames = scene.render_clip_frames(genome, size, 4, 3, n_players=2)
    before = warmup.compiled_signatures()  # after rendering: the renderer is not what is checked

    background, moving = background_from_frames(frames)
    result = pipeline.calibrate(background, moving_mask=moving if moving.any() else None)
    pipeline.draw_overlay(background, result.genome)
    pipeline.evidence_image(background, moving)
    camera.pixel_to_floor(result.genome, np.array([[240.0, 200.0]]))
    camera.floor_to_pixel(result.genome, np.array([[3.2, 5.0]]))

    after = warmup.compiled_signatures()
    new = {name: after[name] - before.get(name, set()) for name in after}
    assert {name: sigs for name, sigs in new.items() if sigs} == {}


def test_unknown_warm_up_is_refused() -> None:
    with pytest.raises(KeyError):
        warmup.warm_up(("nope",))


def test_a_failed_warm_up_does_not_stop_a_service(monkeypatch: pytest.MonkeyPatch) -> None:
    def broken() -> None:
        raise RuntimeError("no compiler today")

    monkeypatch.setitem(warmup.WARM_UPS, "broken", broken)
    with pytest.raises(RuntimeError):
        warmup.warm_up(("broken",))  # the image build must fail
    warmup.warm_up_best_effort(("broken",))  # a starting service logs it and serves
