"""The inspector's web server: the page, and the JSON it polls, on 127.0.0.1 only.

Safe by default, as a local debugging server must be:

- it binds 127.0.0.1 (reach it from elsewhere through an SSH tunnel);
- every URL starts with a random per-run key (``http://127.0.0.1:PORT/KEY/``): without it,
  403;
- a request whose ``Host`` is not ``127.0.0.1``, ``localhost`` or ``[::1]`` (with this port),
  or whose ``Origin``, when sent, is not this server's, gets 403: a page on another site, or a
  DNS name rebound to 127.0.0.1, can neither read nor change anything;
- changes only by ``POST`` with a JSON body (which a cross-site form cannot send without a
  preflight that is never granted); no CORS header is ever sent;
- the environment servers' token stays in :class:`~rlenv_tools.inspector._watch.Watcher`; no
  response carries it.

Routes (below the key): ``/`` the page, ``/static/NAME`` its script and style, and the API:
``GET api/servers``, ``api/frame``, ``api/tree``, ``api/node``, ``api/stats``,
``api/snapshot`` (``?server=S&instance=I``, and ``path`` or ``since``), ``api/control`` (the
demonstration under way) and ``POST api/edit`` (``{"server", "instance", "path", "property",
"value"}``); with demonstrations (:mod:`~rlenv_tools.inspector._control`), ``POST api/control``
(``{"server", "instance"}`` and, with several agents, the ``agent`` to play: take control;
beside a trainer, claim that agent),
``api/keys`` (``{"held": [key, ...]}``) and ``api/release`` (``{}``), under the same rules as
an edit.

With timelines (:mod:`~rlenv_tools.inspector._timelines`: ``rlenv replay FILE --inspect``, or
a watched instance's recent episodes), ``GET api/timelines`` (those offered, the policies),
``api/timeline`` (``?timeline=T``: its length, keys and tree of branches),
``api/timeline/step`` and ``api/timeline/ticks`` (``?timeline=T&branch=B&step=K``; the ticks
a page at a time: ``&first=F&count=N``, at most 100),
``api/timeline/compare`` (``?timeline=T&a=A&b=B&step=K``), ``api/timeline/recent``
(``?server=S&instance=I``: the instance's last finished episodes, each with its ``id``) and
``POST api/timeline/open`` (``{"server", "instance", "id"}``: a recent one as a timeline),
``api/timeline/branch`` (``{"timeline", "branch", "step", "key"}``), ``api/timeline/extend``
(``{"timeline", "branch", "key"}``) and ``api/timeline/policy`` (``{"timeline", "branch",
"step", "policy", "max_steps"}``), under the same rules as an edit.
"""

from __future__ import annotations

import hmac
import json
import logging
import secrets
import threading
from collections.abc import Callable
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from typing import Any
from urllib.parse import parse_qs, urlsplit

from rlenv_tools._origins import OriginPolicy
from rlenv_tools.inspector._control import Demonstrator
from rlenv_tools.inspector._timelines import MAX_TICKS, Timelines, episode_id
from rlenv_tools.inspector._watch import InspectorError, Watcher

__all__ = ["InspectorServer"]

logger = logging.getLogger(__name__)

_MAX_BODY = 64 * 1024
_STATIC = {
    "inspector.js": "text/javascript; charset=utf-8",
    "timeline.js": "text/javascript; charset=utf-8",
    "inspector.css": "text/css; charset=utf-8",
    "index.html": "text/html; charset=utf-8",
}
_HEADERS = {
    "Cache-Control": "no-store",
    "X-Content-Type-Options": "nosniff",
    "X-Frame-Options": "DENY",
    "Referrer-Policy": "no-referrer",
    "Cross-Origin-Resource-Policy": "same-origin",
    "Content-Security-Policy": "default-src 'none'; script-src 'self'; style-src 'self'; "
    "img-src 'self' data:; connect-src 'self'; base-uri 'none'; "
    "form-action 'none'; frame-ancestors 'none'",
}


class InspectorServer(ThreadingHTTPServer):
    """Serves the inspector's page and API for ``watcher`` on ``127.0.0.1:port``.

    Args:
        watcher: the observer connections to the environment servers.
        port: the port to bind (0: a free one).
        key: the URL key (default: a fresh random one).
        demonstrator: lets a person take control and records their episodes (``None``: the
            page only watches).
        timelines: recordings to scrub and branch (default: none but the watched instances'
            recent episodes, opened from the page); closed with the server.
    """

    daemon_threads = True

    def __init__(
        self,
        watcher: Watcher,
        port: int = 0,
        key: str | None = None,
        demonstrator: Demonstrator | None = None,
        timelines: Timelines | None = None,
    ) -> None:
        super().__init__(("127.0.0.1", port), _Handler)
        self.watcher = watcher
        self.demonstrator = demonstrator
        self.timelines = timelines if timelines is not None else Timelines()
        self.key = key or secrets.token_urlsafe(18)
        self.origins = OriginPolicy(self.server_address[1])
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        """The page's address, key included."""
        return f"http://127.0.0.1:{self.server_address[1]}/{self.key}/"

    def start(self) -> None:
        """Serve in a background thread (see :meth:`close`).

        The watched servers are connected first: a server keeps its recent episodes from the
        moment an inspector asks (the watcher does as it connects).
        """
        self.watcher.servers()
        self._thread = threading.Thread(
            target=self.serve_forever, name="rlenv-inspector", daemon=True
        )
        self._thread.start()

    def handle_error(self, request: Any, client_address: Any) -> None:
        """A browser that went away mid-answer is no error of ours: log it quietly."""
        logger.debug("the page at %s went away", client_address, exc_info=True)

    def close(self) -> None:
        """Stop serving, and close the watcher's connections."""
        if self._thread is not None:
            self.shutdown()
            self._thread.join()
            self._thread = None
        self.server_close()
        if self.demonstrator is not None:
            self.demonstrator.close()
        self.timelines.close()
        self.watcher.close()


def _number(query: dict[str, list[str]], name: str, default: int = 0) -> int:
    values = query.get(name)
    if not values:
        return default
    try:
        number = int(values[0])
    except ValueError:
        raise InspectorError(400, f"{name} must be an integer, got {values[0]!r:.40}") from None
    if not 0 <= number < 2**31:
        raise InspectorError(400, f"{name} must be in [0, 2**31), got {number}")
    return number


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a value an edit may carry")


def _text(query: dict[str, list[str]], name: str) -> str:
    values = query.get(name)
    if not values:
        raise InspectorError(400, f"missing {name}")
    return values[0]


_GETS: dict[str, Callable[[Watcher, dict[str, list[str]]], Any]] = {
    "api/servers": lambda watcher, q: watcher.servers(),
    "api/frame": lambda watcher, q: watcher.frame(_number(q, "server"), _number(q, "instance")),
    "api/tree": lambda watcher, q: watcher.tree(_number(q, "server"), _number(q, "instance")),
    "api/node": lambda watcher, q: watcher.node(
        _number(q, "server"), _number(q, "instance"), _text(q, "path")
    ),
    "api/stats": lambda watcher, q: watcher.stats(
        _number(q, "server"), _number(q, "instance"), _number(q, "since")
    ),
    "api/snapshot": lambda watcher, q: watcher.snapshot(
        _number(q, "server"), _number(q, "instance")
    ),
}


def _recent(watcher: Watcher, server: int, instance: int) -> list[Any]:
    """The instance's recent finished episodes (the watched server must keep them)."""
    recent = getattr(watcher, "recent_episodes", None)
    if recent is None:
        raise InspectorError(501, "this inspector cannot list recent episodes")
    return list(recent(server, instance))


def _recent_list(inspector: InspectorServer, query: dict[str, list[str]]) -> list[dict[str, Any]]:
    server, instance = _number(query, "server"), _number(query, "instance")
    episodes = _recent(inspector.watcher, server, instance)
    inspector.timelines.listed(server, instance, episodes)
    return [
        {
            "episode": index,
            "id": episode_id(episode),
            "steps": sum(1 for e in episode.snapshot.get("events", ()) if e[0] == "action"),
            "terminated": episode.terminated,
            "truncated": episode.truncated,
            "target": episode.target,
        }
        for index, episode in enumerate(episodes)
    ]


_TIMELINE_GETS: dict[str, Callable[[Timelines, dict[str, list[str]]], Any]] = {
    "api/timelines": lambda timelines, q: timelines.list(),
    "api/timeline": lambda timelines, q: timelines.describe(_number(q, "timeline")),
    "api/timeline/step": lambda timelines, q: timelines.step(
        _number(q, "timeline"), _number(q, "branch"), _number(q, "step")
    ),
    "api/timeline/ticks": lambda timelines, q: timelines.ticks(
        _number(q, "timeline"),
        _number(q, "branch"),
        _number(q, "step"),
        _number(q, "first", 1),
        _number(q, "count", MAX_TICKS),
    ),
    "api/timeline/compare": lambda timelines, q: timelines.compare(
        _number(q, "timeline"), _number(q, "a"), _number(q, "b", 1), _number(q, "step")
    ),
}


class _Handler(BaseHTTPRequestHandler):
    server: InspectorServer
    protocol_version = "HTTP/1.1"  # the page polls over kept-alive connections
    timeout = 60  # seconds a connection may stay silent, or a body take to arrive
    disable_nagle_algorithm = True  # headers and body go in two writes: never wait for an ACK
    server_version = "rlenv-inspector"
    sys_version = ""

    def do_GET(self) -> None:  # noqa: N802
        route = self._route()
        if route is None:
            return
        path, query = route
        if path == "" and not self.path.split("?")[0].endswith("/"):
            self.send_response(308)  # the page's relative URLs need the trailing slash
            self.send_header("Location", f"/{self.server.key}/")
            self.send_header("Content-Length", "0")
            self.end_headers()
        elif path in ("", "index.html"):
            self._send_static("index.html")
        elif path.startswith("static/") and path[len("static/") :] in _STATIC:
            self._send_static(path[len("static/") :])
        elif path in _GETS:
            self._answer(lambda: _GETS[path](self.server.watcher, query))
        elif path in _TIMELINE_GETS:
            self._answer(lambda: _TIMELINE_GETS[path](self.server.timelines, query))
        elif path == "api/timeline/recent":
            self._answer(lambda: _recent_list(self.server, query))
        elif path == "api/control":
            demonstrator = self.server.demonstrator
            self._send_json(
                200,
                {"enabled": False}
                if demonstrator is None
                else {"enabled": True, **demonstrator.status()},
            )
        else:
            self._send_json(404, {"error": f"no such page: {path!r:.60}"})

    def do_POST(self) -> None:  # noqa: N802
        route = self._route()
        if route is None:
            return
        path, _ = route
        if path not in _POSTS:
            self._send_json(404, {"error": f"nothing to post to at {path!r:.60}"})
            return
        if self.headers.get_content_type() != "application/json":
            self._send_json(
                415, {"error": "a change is a JSON body (Content-Type: application/json)"}
            )
            return
        self._answer(lambda: _POSTS[path](self))

    def do_OPTIONS(self) -> None:  # noqa: N802  (no preflight is ever granted: no CORS)
        self._send_json(405, {"error": "no cross-origin requests"})

    do_PUT = do_DELETE = do_PATCH = do_OPTIONS  # noqa: N815

    def _route(self) -> tuple[str, dict[str, list[str]]] | None:
        """The path below the key and the query, or ``None`` once a refusal is sent."""
        refusal = self.server.origins.refusal(
            self.headers.get("Host", ""), self.headers.get("Origin")
        )
        if refusal is not None:
            self._send_json(403, {"error": refusal})
            return None
        url = urlsplit(self.path)
        key, _, rest = url.path.lstrip("/").partition("/")
        if not hmac.compare_digest(key.encode(), self.server.key.encode()):
            self._send_json(
                403,
                {
                    "error": "refused: the URL lacks this inspector's key "
                    "(use the address it printed)"
                },
            )
            return None
        return rest, parse_qs(url.query)

    def _body(
        self, what: str, expected: set[str], optional: frozenset[str] = frozenset()
    ) -> dict[str, Any]:
        """The request's JSON body: a map of ``expected``, and maybe some of ``optional``.

        ``server`` and ``instance``, when expected, must be integers >= 0.
        """
        length = self.headers.get("Content-Length", "")
        if not length.isdigit() or not 0 < int(length) <= _MAX_BODY:
            raise InspectorError(
                400, f"{what}'s body must be 1 to {_MAX_BODY} bytes, with its Content-Length"
            )
        try:
            body = json.loads(self.rfile.read(int(length)), parse_constant=_no_constant)
        except ValueError as error:
            raise InspectorError(400, f"{what}'s body is not JSON: {error}") from None
        if not isinstance(body, dict) or not expected <= set(body) <= expected | optional:
            also = f" (and maybe {sorted(optional)})" if optional else ""
            raise InspectorError(400, f"{what} is a map of exactly {sorted(expected)}{also}")
        for name in ("server", "instance", "timeline", "branch", "step", "episode", "max_steps"):
            if name in body and (type(body[name]) is not int or not 0 <= body[name] < 2**31):
                raise InspectorError(400, f"{name} must be an integer >= 0")
        for name in ("key", "policy", "id", "agent"):
            if name in body and (not isinstance(body[name], str) or len(body[name]) > 64):
                raise InspectorError(400, f"{name} must be a string (at most 64 characters)")
        return body

    def _open_recent(self) -> Any:
        body = self._body("opening a recent episode", {"server", "instance", "id"})
        episodes = _recent(self.server.watcher, body["server"], body["instance"])
        return self.server.timelines.open_recent(
            episodes, body["server"], body["instance"], body["id"]
        )

    def _branch_keys(self) -> Any:
        body = self._body("a key branch", {"timeline", "branch", "step", "key"})
        return self.server.timelines.branch_keys(
            body["timeline"], body["branch"], body["step"], body["key"]
        )

    def _extend(self) -> Any:
        body = self._body("a key step", {"timeline", "branch", "key"})
        return self.server.timelines.extend(body["timeline"], body["branch"], body["key"])

    def _branch_policy(self) -> Any:
        body = self._body("a policy branch", {"timeline", "branch", "step", "policy", "max_steps"})
        return self.server.timelines.branch_policy(
            body["timeline"], body["branch"], body["step"], body["policy"], body["max_steps"]
        )

    def _edit(self) -> Any:
        edit = self._body("an edit", {"server", "instance", "path", "property", "value"})
        for name in ("path", "property"):
            if not isinstance(edit[name], str):
                raise InspectorError(400, f"{name} must be a string")
        scope = self.server.watcher.edit(
            edit["server"], edit["instance"], edit["path"], edit["property"], edit["value"]
        )
        return {"scope": scope}

    def _demonstrator(self) -> Demonstrator:
        if self.server.demonstrator is None:
            raise InspectorError(
                404, "demonstrations are off: start the inspector with --record-demonstrations DIR"
            )
        return self.server.demonstrator

    def _take(self) -> Any:
        body = self._body("taking control", {"server", "instance"}, frozenset({"agent"}))
        return self._demonstrator().take(body["server"], body["instance"], body.get("agent"))

    def _keys(self) -> Any:
        held = self._body("a key change", {"held"})["held"]
        if (
            not isinstance(held, list)
            or not all(isinstance(key, str) for key in held)
            or len(held) > 32
        ):
            raise InspectorError(400, "held is a list of at most 32 key names")
        return self._demonstrator().hold(held)

    def _release(self) -> Any:
        self._body("a release", set())
        return self._demonstrator().release()

    def _answer(self, compute: Callable[[], Any]) -> None:
        try:
            self._send_json(200, compute())
        except InspectorError as error:
            self._send_json(error.status, {"error": str(error)})
        except Exception as error:  # our bug: the page says so, the server goes on
            logger.exception("inspector request %s failed", self.path)
            self._send_json(500, {"error": f"the inspector failed: {error!r:.200}"})

    def _send_static(self, name: str) -> None:
        body = resources.files("rlenv_tools.inspector").joinpath("static", name).read_bytes()
        self._send(200, _STATIC[name], body)

    def _send_json(self, status: int, value: Any) -> None:
        try:
            body = json.dumps(value, separators=(",", ":"), allow_nan=False).encode()
        except ValueError as error:  # a NaN in a scene that blew up, say
            status, body = 500, json.dumps({"error": f"cannot show this: {error}"}).encode()
        self._send(status, "application/json", body)

    def _send(self, status: int, content_type: str, body: bytes) -> None:
        if status >= 400 and self.command == "POST":  # its body may be unread: start afresh
            self.close_connection = True
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        for name, value in _HEADERS.items():
            self.send_header(name, value)
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 (http.server's name)
        logger.debug("%s %s", self.address_string(), format % args)


_POSTS: dict[str, Callable[[_Handler], Any]] = {
    "api/edit": _Handler._edit,
    "api/control": _Handler._take,
    "api/keys": _Handler._keys,
    "api/release": _Handler._release,
    "api/timeline/open": _Handler._open_recent,
    "api/timeline/branch": _Handler._branch_keys,
    "api/timeline/extend": _Handler._extend,
    "api/timeline/policy": _Handler._branch_policy,
}
