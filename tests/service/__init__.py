"""Service tests: API, queue, worker, migrations, end to end."""
