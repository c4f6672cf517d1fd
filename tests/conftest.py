import numpy as np
import pytest

from app.calib import camera


@pytest.fixture
def target_genome() -> np.ndarray:
    """A broadcast-like camera behind the back wall, 1920x1080, with barrel distortion."""
    g = np.zeros(camera.N_GENES)
    g[:4] = [1500.0, 1500.0, 960.0, 540.0]
    g[4:7] = [0.0, 2.3, 8.5]
    g[7] = 0.3
    g[10:15] = [-0.12, 0.05, 0.001, -0.0005, 0.0]
    return g
