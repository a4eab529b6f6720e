# ruff: noqa: F811 - pytest fixtures are imported by name from test_api_common
"""The OpenAPI document is complete: every operation of the API with its summary, request
body forms, security and the problems it can answer with."""

from __future__ import annotations

import pytest

from tests.web_api.test_api_common import (  # noqa: F401 - fixtures
    SQLITE_ONLY,
    api,
    engine,
    pg_url,
    sessions,
    sqlite_template,
)

pytestmark = SQLITE_ONLY

OPERATIONS = {
    ("get", "/api/health"),
    ("get", "/api/whoami"),
    ("post", "/api/programs"),
    ("get", "/api/programs"),
    ("get", "/api/programs/{program_id}"),
    ("post", "/api/programs/{program_id}/revisions"),
    ("get", "/api/revisions/{revision_id}"),
    ("get", "/api/revisions/{revision_id}/text"),
    ("get", "/api/revisions/{revision_id}/calls"),
    ("post", "/api/revisions/{revision_id}/release"),
    ("get", "/api/revisions/{a}/diff/{b}"),
    ("get", "/api/revisions/{revision_id}/posted"),
    ("get", "/api/revisions/{revision_id}/derived"),
    ("get", "/api/derived-revisions/{derived_id}/text"),
    ("post", "/api/dispatches"),
    ("get", "/api/dispatches"),
    ("get", "/api/dispatches/{dispatch_id}"),
    ("post", "/api/jobs"),
    ("get", "/api/jobs"),
    ("get", "/api/jobs/{job_id}"),
    ("post", "/api/jobs/{job_id}/cancel"),
    ("get", "/api/machines"),
    ("get", "/api/machines/{name}"),
    ("get", "/api/events"),
}


@pytest.fixture
def doc(api):
    return api.client.get("/openapi.json").json()


def operations(doc):
    return {
        (method, path): op
        for path, item in doc["paths"].items()
        for method, op in item.items()
        if method in ("get", "post", "put", "patch", "delete")
    }


def test_every_operation_is_documented_with_a_summary(doc):
    ops = operations(doc)
    assert set(ops) == OPERATIONS
    assert all(op.get("summary") for op in ops.values())


def test_every_protected_operation_declares_its_keys_and_auth_problems(doc):
    schemes = doc["components"]["securitySchemes"]
    assert schemes["ApiKey"] == {"type": "apiKey", "in": "header", "name": "X-API-Key"}
    assert schemes["Bearer"]["scheme"] == "bearer"
    for key, op in operations(doc).items():
        if key == ("get", "/api/health"):
            assert "security" not in op and "503" in op["responses"]
            continue
        assert {"ApiKey": []} in op["security"], key
        takes_input = op.get("parameters") or op.get("requestBody")
        for status in ("401", "403", "422") if takes_input else ("401", "403"):
            content = op["responses"][status]["content"]
            assert content == {
                "application/problem+json": {"schema": {"$ref": "#/components/schemas/Problem"}}
            }, (key, status)


def test_uploads_document_json_and_multipart(doc):
    for path in ("/api/programs", "/api/programs/{program_id}/revisions"):
        content = doc["paths"][path]["post"]["requestBody"]["content"]
        assert set(content) == {"application/json", "multipart/form-data"}
        ref = content["application/json"]["schema"]["$ref"].rsplit("/", 1)[-1]
        assert ref in doc["components"]["schemas"]
        assert content["multipart/form-data"]["schema"]["properties"]["file"]["format"] == "binary"


def test_dispatch_documents_idempotency_and_both_success_codes(doc):
    op = doc["paths"]["/api/dispatches"]["post"]
    header = next(p for p in op["parameters"] if p["name"] == "Idempotency-Key")
    assert header["in"] == "header" and header["required"] is True
    assert {"200", "202", "404", "409", "422"} <= set(op["responses"])


def test_text_responses_have_their_media_types(doc):
    text = doc["paths"]["/api/revisions/{revision_id}/text"]["get"]["responses"]["200"]
    assert "text/plain" in text["content"]
    diff = doc["paths"]["/api/revisions/{a}/diff/{b}"]["get"]["responses"]["200"]
    assert "text/x-diff" in diff["content"]
    events = doc["paths"]["/api/events"]["get"]["responses"]["200"]
    assert "text/event-stream" in events["content"]
