"""Database layer: models, sessions, tenant-scoped repository, the job queue and migrations."""
