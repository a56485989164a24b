"""Schemathesis checks shared by the fuzzing tests. schemathesis keeps one global registry of check
names, so a check is registered here once per process, not in each test module."""

from __future__ import annotations

import schemathesis


@schemathesis.check
def no_internal_error(ctx, response, case) -> None:
    """Any 5xx except 503: a 503 is a deliberate, documented answer ("the 3D view is not running")."""
    if response.status_code >= 500 and response.status_code != 503:
        raise AssertionError(
            f"{response.status_code} from {case.method} {case.formatted_path}: {response.text[:300]}"
        )
