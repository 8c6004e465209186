"""An HTTP/JSON gateway to rlenv environments: ``rlenv http [TARGET]`` (the ``http`` extra).

A program in any language, or curl, drives environments without a msgpack client:
gym-http-api's sessions under ``/v1/envs``, bevy_rl's routes on the command line's TARGET, a
WebSocket and server-sent events per session, RFC 9457 problems for every error, and an
OpenAPI 3.1 document generated from the route table. ``docs/http.md`` is the guide.

One module per job (importing this package imports none of them, nor Starlette):

- :mod:`~rlenv_tools.http.app`: the Starlette application and uvicorn's server (``serve``);
  :mod:`~rlenv_tools.http._uvicorn_protocol`: one write per response, a deadline
  on request heads, a bound on connections (uvicorn's internals, on tested versions only);
- :mod:`~rlenv_tools.http._guard`: Host, Origin, token and body size, checked before any route;
- :mod:`~rlenv_tools.http._endpoints`: the route record, JSON bodies in and out;
- :mod:`~rlenv_tools.http._routes`: the ``/v1`` session API;
  :mod:`~rlenv_tools.http._bevy`: bevy_rl's routes;
  :mod:`~rlenv_tools.http._streams`: the WebSocket and the event stream;
- :mod:`~rlenv_tools.http._openapi`: the OpenAPI document from the route table;
- :mod:`~rlenv_tools.http._sessions`: sessions, limits, the idle reaper;
- :mod:`~rlenv_tools.http._targets`: what an ``env_id`` names and where its environment runs;
- :mod:`~rlenv_tools.http._runners`: how a call reaches an environment, under a deadline;
- :mod:`~rlenv_tools.http.problems`: errors as problem details;
- :mod:`~rlenv_tools.http.json_spaces`: spaces, JSON Schemas and values as JSON;
  :mod:`~rlenv_tools.http._png`: PNG images.
"""
