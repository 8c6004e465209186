"""Serving requests: the path a request takes through the server.

- :mod:`~rlenv.serving.endpoint`: sockets (clients, the controller, limits, deadlines, token);
- :mod:`~rlenv.serving.host`: K instances answering as one server, by one door;
- :mod:`~rlenv.serving.parts`: one record per kind of request part (check, apply, control);
- :mod:`~rlenv.serving.instance`: one environment in its own tree, and its episode's state;
- :mod:`~rlenv.serving.columns`: the answer of a ``steps`` request, in columns;
- :mod:`~rlenv.serving.snapshots`: the episode as data, to restore anywhere;
- :mod:`~rlenv.serving.inspector`: the node tree and exported properties, remotely.

Nothing here is imported by ``rlenv_client`` unless an environment runs in its process.
"""
