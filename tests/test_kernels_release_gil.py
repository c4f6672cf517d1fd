"""The compiled kernels a calibration spends seconds in release the GIL: the worker's heartbeat
thread must renew the job's lease while a search runs, or a live worker loses its job to
another (at 1080p one call of the coarse ranking holds the interpreter for seconds). So do those
of /project's pixel -> floor (undistortion, the ray's plane), which the API runs in its thread
pool beside other requests."""

import pytest

from app.calib import camera, lines, placement, refine, search, segments, verify

LONG_KERNELS = [
    search._hypotheses_njit,
    search._wall_hypotheses_njit,
    search._poses_njit,
    verify._coarse_njit,
    verify._verify_njit,
    placement._floor_share_njit,
    placement._in_play_volume_all,
    lines._best_ridge,
    lines._ridge_centres,
    lines._steps,
    refine._residuals_njit,
    camera._extrinsics_all,
    camera._project_all,
    camera._fold_radii_njit,
    camera._undistort_njit,
    camera._pixels_to_plane_njit,
    segments._link,
]


@pytest.mark.parametrize("kernel", LONG_KERNELS, ids=lambda k: k.py_func.__name__)
def test_long_kernel_releases_the_gil(kernel):
    assert kernel.targetoptions.get("nogil") is True
