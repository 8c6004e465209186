"""Errors as RFC 9457 problem details: ``application/problem+json``, never an HTML page.

Every refusal and failure of the gateway is a :class:`Problem` with ``type``, ``title``,
``status`` and ``detail``, the request's path as ``instance``, and the error code as the
extension member ``code``: the protocol's own code (:class:`rlenv.protocol.errors.ErrorCode`)
when the environment refused the request, or one of the gateway's (``unknown_session``,
``session_limit``, ``environment_lost`` ...). :data:`PROBLEMS` is the one table of codes,
statuses and titles; ``type`` is ``urn:rlenv:problem:`` and the code.

No request can stop the gateway: a refused request changes nothing, and the next one is served.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, NamedTuple

from starlette.responses import Response

from rlenv.protocol.errors import ErrorCode, RemoteError
from rlenv_tools.http.json_spaces import dumps

__all__ = [
    "COMMON_HEADERS",
    "PROBLEMS",
    "PROBLEM_MEDIA_TYPE",
    "PROBLEM_TYPE",
    "Problem",
    "ProblemKind",
    "from_remote_error",
]

PROBLEM_MEDIA_TYPE = "application/problem+json"
PROBLEM_TYPE = "urn:rlenv:problem:"
"""The prefix of every problem's ``type``; the code follows it."""

COMMON_HEADERS: Mapping[str, str] = {
    "Cache-Control": "no-store",
    "X-Content-Type-Options": "nosniff",
}
"""Headers of every answer: nothing is cached, nothing is sniffed into another type."""


class ProblemKind(NamedTuple):
    """The status and title of one kind of problem."""

    status: int
    title: str


PROBLEMS: dict[str, ProblemKind] = {
    ErrorCode.BAD_REQUEST: ProblemKind(400, "Bad request"),
    ErrorCode.BAD_FRAME: ProblemKind(400, "Bad request"),
    ErrorCode.UNAUTHORIZED: ProblemKind(401, "Token required"),
    "forbidden": ProblemKind(403, "Forbidden"),
    "not_found": ProblemKind(404, "Not found"),
    "unknown_session": ProblemKind(404, "Unknown session"),
    "method_not_allowed": ProblemKind(405, "Method not allowed"),
    ErrorCode.RESET_REQUIRED: ProblemKind(409, "Reset required"),
    ErrorCode.BUSY: ProblemKind(409, "Environment busy"),
    "payload_too_large": ProblemKind(413, "Body too large"),
    ErrorCode.INVALID_ACTION: ProblemKind(422, "Action outside the space"),
    ErrorCode.INVALID_CONFIG: ProblemKind(422, "Configuration refused"),
    ErrorCode.ENVIRONMENT_ERROR: ProblemKind(500, "Environment error"),
    "internal_error": ProblemKind(500, "Gateway error"),
    "environment_lost": ProblemKind(502, "Environment lost"),
    "session_limit": ProblemKind(503, "Too many sessions"),
    ErrorCode.TIMEOUT: ProblemKind(504, "Environment timed out"),
}
"""Every problem the gateway answers, by code. ``bad_request``: malformed JSON or a bad body;
``reset_required``: a step before a reset or after the episode ended; ``invalid_action``: an
action outside the space; ``session_limit``: comes with ``Retry-After``; ``timeout``: the
environment did not answer in time (the session is closed); ``environment_lost``: the
environment's server died (the session says so; the others go on)."""

_UNKNOWN = ProblemKind(502, "Unexpected answer from the environment")


class Problem(Exception):
    """A problem to answer with (see the module docstring).

    Args:
        code: a code of :data:`PROBLEMS` (another one, from an environment server, is a 502).
        detail: what happened, for a person: precise, naming the field or the value.
        headers: extra response headers (``Retry-After``, ``WWW-Authenticate``).
        members: extension members added to the body.
    """

    def __init__(
        self, code: str, detail: str, *, headers: Mapping[str, str] | None = None, **members: Any
    ) -> None:
        super().__init__(detail)
        self.code = str(code)
        self.kind = PROBLEMS.get(self.code, _UNKNOWN)
        self.detail = detail
        self.headers = dict(headers or {})
        self.members = members

    @property
    def status(self) -> int:
        """The HTTP status."""
        return self.kind.status

    def to_json(self, instance: str | None = None) -> dict[str, Any]:
        """The problem details object."""
        body: dict[str, Any] = {
            "type": PROBLEM_TYPE + self.code,
            "title": self.kind.title,
            "status": self.kind.status,
            "detail": self.detail,
            "code": self.code,
        }
        if instance is not None:
            body["instance"] = instance
        body.update(self.members)
        return body

    def response(self, instance: str | None = None) -> Response:
        """The ``application/problem+json`` response."""
        return Response(
            dumps(self.to_json(instance)),
            self.kind.status,
            headers={**COMMON_HEADERS, **self.headers},
            media_type=PROBLEM_MEDIA_TYPE,
        )


def from_remote_error(error: RemoteError) -> Problem:
    """The problem of an environment's refusal (its code and message, as over TCP)."""
    return Problem(error.code, error.message)
