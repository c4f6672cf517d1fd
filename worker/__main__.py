"""`python -m worker`: one worker process with the settings from the environment."""

import sys

from app.settings import get_settings
from worker.main import run_worker

sys.exit(run_worker(get_settings()))
