"""Fuzz the HTTP API from its own OpenAPI document: no answer is a server error.

The API runs in a real Service over simulated lines (in a thread of its own, since
schemathesis calls synchronously), so generated commands and parameter accesses travel to
simulated drives and back.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
import schemathesis
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from schemathesis.checks import not_a_server_error
from schemathesis.specs.openapi.checks import (
    content_type_conformance,
    response_headers_conformance,
    response_schema_conformance,
    status_code_conformance,
)

from tests.integration.http_harness import OPERATOR, ServiceThread, service_config
from tests.integration.ports import free_port

DRIVES = ("pump-1", "pump-2", "fan-1", "fan-2")
PARAMETERS = ("16-13", "3-41", "1-20", "15-43", "99-99")


@pytest.fixture(scope="module")
def api() -> Iterator[ServiceThread]:
    port = free_port()
    service = ServiceThread(service_config(port), port)
    service.start()
    try:
        yield service
    finally:
        service.stop()


@pytest.fixture(scope="module")
def api_schema(api: ServiceThread) -> schemathesis.BaseSchema:
    loaded = schemathesis.openapi.from_url(api.url + "/api/v1/openapi.json")

    @loaded.hook
    def flatmap_path_parameters(
        context: schemathesis.HookContext, path_parameters: dict[str, Any] | None
    ) -> st.SearchStrategy[dict[str, Any] | None]:
        """Mostly real drives and parameters, so commands reach simulated drives too."""
        if not isinstance(path_parameters, dict):
            return st.just(path_parameters)
        names = st.sampled_from([path_parameters.get("name", ""), *DRIVES])
        params = st.sampled_from([path_parameters.get("param", ""), *PARAMETERS])
        return st.fixed_dictionaries(
            {
                **{key: st.just(value) for key, value in path_parameters.items()},
                **({"name": names} if "name" in path_parameters else {}),
                **({"param": params} if "param" in path_parameters else {}),
            }
        )

    return loaded


schema = schemathesis.pytest.from_fixture("api_schema")

# Every answer is documented and matches its schema, and none is a 5xx. Left out on purpose:
# negative_data_rejection (unknown query parameters are ignored, as HTTP APIs do) and
# positive_data_acceptance (a schema-valid name of a drive that does not exist is a 404, and
# a command the drive refuses is a 409: both are right answers, not failures).
CHECKS = [
    not_a_server_error,
    status_code_conformance,
    content_type_conformance,
    response_schema_conformance,
    response_headers_conformance,
]


@schema.parametrize()
@settings(max_examples=60, suppress_health_check=list(HealthCheck))
def test_the_api_never_answers_with_a_server_error(case: schemathesis.Case[Any]) -> None:
    case.call_and_validate(headers=OPERATOR, checks=CHECKS)
