"""What a failed job's exception means: the job's error code, whether another attempt may succeed,
and whether the log needs the traceback.

One explicit table, read top to bottom, first match wins (so subclasses come before their bases).
Bad input is only what the upload checks and the court search report as such (`MediaError`,
`CourtNotFound`). Anything else, including a `ValueError` out of our own numerics, is a bug or an
outage on our side: `internal_error`, logged with its traceback, retried with backoff.
"""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy.exc import SQLAlchemyError

from app.calib.pipeline import CourtNotFound
from app.media import MediaError


@dataclass(frozen=True)
class FailureKind:
    code: str
    retryable: bool
    # an exception nobody planned for: the operator needs the traceback to fix it
    log_traceback: bool


@dataclass(frozen=True)
class Failure:
    code: str
    message: str
    retryable: bool
    log_traceback: bool


FAILURE_TABLE: tuple[tuple[type[Exception], FailureKind], ...] = (
    # the footage: another attempt sees the same bytes
    (MediaError, FailureKind("invalid_media", retryable=False, log_traceback=False)),
    (CourtNotFound, FailureKind("court_not_found", retryable=False, log_traceback=False)),
    # the machine or its services: may well work on another attempt, on another worker
    (MemoryError, FailureKind("out_of_memory", retryable=True, log_traceback=True)),
    (SQLAlchemyError, FailureKind("database_error", retryable=True, log_traceback=True)),
    (OSError, FailureKind("storage_error", retryable=True, log_traceback=True)),
    # our code: ValueError, IndexError, FloatingPointError, ... are bugs, not invalid input
    (Exception, FailureKind("internal_error", retryable=True, log_traceback=True)),
)


def classify(exc: Exception) -> Failure:
    """The failure a job records for `exc` (the first row of FAILURE_TABLE that matches)."""
    kind = next(kind for exc_type, kind in FAILURE_TABLE if isinstance(exc, exc_type))
    if isinstance(exc, MediaError):  # the media check names the problem itself
        return Failure(exc.code, exc.message, kind.retryable, kind.log_traceback)
    # an unexpected exception's type is half of what it says ("KeyError: 'x'")
    message = f"{type(exc).__name__}: {exc}" if kind.log_traceback else str(exc)
    return Failure(kind.code, message, kind.retryable, kind.log_traceback)
