"""``GET /openapi.json``: OpenAPI 3.1, generated from the route table and the spaces.

Nothing is written twice: the paths, operations, parameters, bodies, answers and problem
statuses come from the :class:`~rlenv_tools.http._endpoints.Endpoint` records that Starlette serves;
``Action`` and ``Observation`` are the JSON Schemas of the TARGET's spaces
(:func:`rlenv_tools.http.json_spaces.json_schema`); the problems' statuses and titles come from
:data:`rlenv_tools.http.problems.PROBLEMS`.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from typing import Any

from rlenv_tools.http._endpoints import JSON, Answer, Endpoint
from rlenv_tools.http.problems import PROBLEM_MEDIA_TYPE, PROBLEM_TYPE, PROBLEMS

__all__ = ["openapi_document"]

_PATH_PARAMETER = re.compile(r"{(\w+)}")
_EVERY_ROUTE = ("forbidden", "internal_error")  # Host/Origin refused; the gateway's own bug


def openapi_document(
    endpoints: Iterable[Endpoint],
    schemas: Mapping[str, Any],
    *,
    title: str,
    version: str,
    description: str,
    token_required: bool,
) -> dict[str, Any]:
    """The OpenAPI 3.1 document of ``endpoints``.

    Args:
        endpoints: the routes, as served.
        schemas: the component schemas their bodies and answers name.
        title: the API's title.
        version: the API's version.
        description: what it is, in Markdown.
        token_required: every request needs ``Authorization: Bearer``.
    """
    paths: dict[str, dict[str, Any]] = {}
    for endpoint in endpoints:
        method = "get" if endpoint.method == "WEBSOCKET" else endpoint.method.lower()
        paths.setdefault(endpoint.path, {})[method] = _operation(endpoint, token_required)
    document: dict[str, Any] = {
        "openapi": "3.1.0",
        "jsonSchemaDialect": "https://json-schema.org/draft/2020-12/schema",
        "info": {"title": title, "version": version, "description": description},
        "paths": paths,
        "components": {"schemas": {"Problem": _PROBLEM, **schemas}},
    }
    if token_required:
        document["components"]["securitySchemes"] = {"bearer": {"type": "http", "scheme": "bearer"}}
        document["security"] = [{"bearer": []}]
    return document


def _operation(endpoint: Endpoint, token_required: bool) -> dict[str, Any]:
    operation: dict[str, Any] = {
        "operationId": endpoint.operation,
        "summary": endpoint.summary,
        "tags": [endpoint.tag],
    }
    description = endpoint.description
    if endpoint.method == "WEBSOCKET":
        description = f"A WebSocket (GET with Upgrade: websocket). {description}".strip()
    if description:
        operation["description"] = description
    parameters = [
        {"name": name, "in": "path", "required": True, "schema": {"type": "string"}}
        for name in _PATH_PARAMETER.findall(endpoint.path)
    ]
    parameters += [
        {
            "name": p.name,
            "in": "query",
            "required": p.required,
            "schema": p.schema,
            "description": p.description,
        }
        for p in endpoint.query
    ]
    if parameters:
        operation["parameters"] = parameters
    if endpoint.body is not None:
        operation["requestBody"] = {
            "required": endpoint.body_required,
            "content": {JSON: {"schema": _schema(endpoint.body)}},
        }
    responses = {str(status): _answer(answer) for status, answer in endpoint.answers.items()}
    problems = [*endpoint.problems, *_EVERY_ROUTE]
    if token_required:
        problems.append("unauthorized")
    if endpoint.body is not None:
        problems += ["payload_too_large", "bad_request"]
    responses.update(_problem_answers(problems))
    operation["responses"] = dict(sorted(responses.items()))
    return operation


def _answer(answer: Answer) -> dict[str, Any]:
    described: dict[str, Any] = {"description": answer.description}
    if answer.media_type:
        described["content"] = {answer.media_type: {"schema": _schema(answer.schema)}}
    return described


def _problem_answers(codes: Iterable[str]) -> dict[str, Any]:
    """One answer per status, naming every problem of that status the route may answer."""
    by_status: dict[int, list[str]] = {}
    for code in dict.fromkeys(str(code) for code in codes):
        by_status.setdefault(PROBLEMS[code].status, []).append(code)
    answers = {}
    for status, codes_of_status in by_status.items():
        named = "; ".join(f"{PROBLEMS[code].title} ({code})" for code in codes_of_status)
        answers[str(status)] = {
            "description": named,
            "content": {PROBLEM_MEDIA_TYPE: {"schema": {"$ref": "#/components/schemas/Problem"}}},
        }
    return answers


def _schema(schema: Any) -> Any:
    if isinstance(schema, str):
        return {"$ref": f"#/components/schemas/{schema}"}
    return schema if schema is not None else {}


_PROBLEM = {
    "type": "object",
    "required": ["type", "title", "status", "detail", "code"],
    "description": "RFC 9457 problem details; code is the protocol's error code or the "
    f"gateway's; type is {PROBLEM_TYPE!r} and the code",
    "properties": {
        "type": {"type": "string", "format": "uri"},
        "title": {"type": "string"},
        "status": {"type": "integer"},
        "detail": {"type": "string"},
        "code": {"enum": sorted(str(code) for code in PROBLEMS)},
        "instance": {"type": "string"},
    },
}
