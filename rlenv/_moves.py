"""Every module that moved, by its old name.

Each keeps working for one release, with a ``DeprecationWarning`` naming its new place
(:func:`rlenv._deprecation.forward`).

The three layers (CHANGELOG, [Unreleased]): the tools left ``rlenv`` and ``rlenv_client`` for
``rlenv_tools``, and the modules that are not the public API (the docs' reference) took a
leading underscore. A chain resolves in one step: ``rlenv_client.origins`` is
``rlenv_tools._origins``.
"""

from __future__ import annotations

MOVES: dict[str, str] = {
    # the tools, out of the runtime and the client
    "rlenv.cli": "rlenv_tools.cli",
    "rlenv.http": "rlenv_tools.http",
    "rlenv.scene2d.views": "rlenv.views",
    "rlenv_client.bench": "rlenv_tools.bench",
    "rlenv_client.checks": "rlenv_tools.checks",
    "rlenv_client.compliance": "rlenv_tools.compliance",
    "rlenv_client.datasets": "rlenv_tools.datasets",
    "rlenv_client.demonstrations": "rlenv_tools.demonstrations",
    "rlenv_client.forking": "rlenv_tools.forking",
    "rlenv_client.inspector": "rlenv_tools.inspector",
    "rlenv_client.observations": "rlenv_tools.observations",
    "rlenv_client.onnx_actors": "rlenv_tools.onnx_actors",
    "rlenv_client.origins": "rlenv_tools.origins",
    "rlenv_client.policies": "rlenv_tools.policies",
    "rlenv_client.timeline": "rlenv_tools.timeline",
    "rlenv_client.training_speed": "rlenv_tools.training_speed",
    # modules that are not the public API
    "rlenv.scene2d.chipmunk": "rlenv.scene2d._chipmunk",
    "rlenv.scene2d.physics.space_owner": "rlenv.scene2d.physics._space_owner",
    "rlenv.scene2d.pymunk_data": "rlenv.scene2d._pymunk_data",
    "rlenv.scene2d.scene_codecs": "rlenv.scene2d._scene_codecs",
    "rlenv.serving.access": "rlenv.serving._access",
    "rlenv.serving.actions": "rlenv.serving._actions",
    "rlenv.serving.claims": "rlenv.serving._claims",
    "rlenv.serving.columns": "rlenv.serving._columns",
    "rlenv.serving.connections": "rlenv.serving._connections",
    "rlenv.serving.endpoint": "rlenv.serving._endpoint",
    "rlenv.serving.host": "rlenv.serving._host",
    "rlenv.serving.inspector": "rlenv.serving._inspector",
    "rlenv.serving.instance": "rlenv.serving._instance",
    "rlenv.serving.lean": "rlenv.serving._lean",
    "rlenv.serving.observing": "rlenv.serving._observing",
    "rlenv.serving.parts": "rlenv.serving._parts",
    "rlenv.serving.penalties": "rlenv.serving._penalties",
    "rlenv.serving.properties": "rlenv.serving._properties",
    "rlenv.serving.recent": "rlenv.serving._recent",
    "rlenv.serving.settings": "rlenv.serving._settings",
    "rlenv.serving.snapshots": "rlenv.serving._snapshots",
    "rlenv.serving.stats": "rlenv.serving._stats",
    "rlenv.serving.target_hints": "rlenv.serving._target_hints",
    "rlenv.transport.procfs": "rlenv.transport._procfs",
    "rlenv_client.addresses": "rlenv_client._addresses",
    "rlenv_client.display": "rlenv_client._display",
    "rlenv_client.rows": "rlenv_client._rows",
    "rlenv_tools.bench": "rlenv_tools._bench",
    "rlenv_tools.checks": "rlenv_tools._checks",
    "rlenv_tools.onnx_actors": "rlenv_tools._onnx_actors",
    "rlenv_tools.origins": "rlenv_tools._origins",
    "rlenv_tools.compliance.contract": "rlenv_tools.compliance._contract",
    "rlenv_tools.compliance.determinism": "rlenv_tools.compliance._determinism",
    "rlenv_tools.compliance.harness": "rlenv_tools.compliance._harness",
    "rlenv_tools.compliance.hostile": "rlenv_tools.compliance._hostile",
    "rlenv_tools.http.bevy": "rlenv_tools.http._bevy",
    "rlenv_tools.http.endpoints": "rlenv_tools.http._endpoints",
    "rlenv_tools.http.guard": "rlenv_tools.http._guard",
    "rlenv_tools.http.openapi": "rlenv_tools.http._openapi",
    "rlenv_tools.http.png": "rlenv_tools.http._png",
    "rlenv_tools.http.routes": "rlenv_tools.http._routes",
    "rlenv_tools.http.runners": "rlenv_tools.http._runners",
    "rlenv_tools.http.sessions": "rlenv_tools.http._sessions",
    "rlenv_tools.http.streams": "rlenv_tools.http._streams",
    "rlenv_tools.http.targets": "rlenv_tools.http._targets",
    "rlenv_tools.http.uvicorn_protocol": "rlenv_tools.http._uvicorn_protocol",
    "rlenv_tools.inspector.control": "rlenv_tools.inspector._control",
    "rlenv_tools.inspector.timelines": "rlenv_tools.inspector._timelines",
    "rlenv_tools.inspector.watch": "rlenv_tools.inspector._watch",
    "rlenv_tools.inspector.web": "rlenv_tools.inspector._web",
}
