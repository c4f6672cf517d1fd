"""Property-based contract test: schemathesis drives every operation of the OpenAPI document
against the ASGI app (in process). Zero 5xx and zero schema violations; the number of cases is
printed.

Bounded (MAX_EXAMPLES per operation and mode, about a minute) and marked slow; run it with
`.venv/bin/python -m pytest -q -s -m slow tests/service/test_schemathesis.py`.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings
from hypothesis.errors import Unsatisfiable
from schemathesis.core.failures import FailureGroup

from app.api.demo import demo_clip_path
from app.db.migrate import upgrade_head
from app.main import create_app
from tests.service.conftest import make_settings, new_key

MAX_EXAMPLES = 20


def _exercise(
    operation: schemathesis.APIOperation, mode: schemathesis.GenerationMode, auth: dict[str, str]
) -> tuple[int, Counter]:
    """Run one operation's cases (valid or invalid data); returns (cases, failures by message)."""
    statuses: Counter[int] = Counter()
    failures: Counter[str] = Counter()

    @given(case=operation.as_strategy(generation_mode=mode))
    @settings(
        max_examples=MAX_EXAMPLES,
        deadline=None,
        suppress_health_check=list(HealthCheck),
        derandomize=True,
        database=None,
    )
    def run(case: schemathesis.Case) -> None:
        try:
            # a case that tests a missing key must go without one
            negated = operation.schema.is_security_param_negated(case)
            response = case.call_and_validate(headers=None if negated else auth, timeout=60)
            statuses[response.status_code] += 1
        except (
            Exception,
            FailureGroup,
        ) as exc:  # every check's failure, collected to report them all at once
            statuses[-1] += 1
            failures[
                f"{operation.label} ({mode.value}): {type(exc).__name__}: {str(exc)[:600]}"
            ] += 1

    try:
        run()
    except Unsatisfiable:  # nothing can be invalid about it (no parameters, no body)
        assert mode == schemathesis.GenerationMode.NEGATIVE
    return sum(statuses.values()), failures


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_api_honours_its_openapi_document(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    app_settings = make_settings(tmp_path / "data", max_upload_bytes=2_000_000)
    upgrade_head(app_settings)
    # the demo clip is rendered on its first request (seconds): render it before the clock runs
    demo_clip_path(app_settings.media_dir)
    auth = {"Authorization": f"Bearer {new_key(app_settings)}"}
    schema = schemathesis.openapi.from_asgi("/openapi.json", create_app(app_settings))
    cases = 0
    failures: Counter[str] = Counter()
    operations = 0
    for result in schema.get_all_operations():
        operation = result.ok()
        operations += 1
        for mode in schemathesis.GenerationMode:
            n, failed = _exercise(operation, mode, auth)
            cases += n
            failures.update(failed)
    # shown on a passing run too: CI's log is where the number of cases tried is read
    with capsys.disabled():
        print(
            f"\nschemathesis: {cases} cases over {operations} operations, {len(failures)} failures"
        )
        for message, count in failures.most_common():
            print(f"  x{count} {message}\n")
    assert cases > 0
    assert not failures
