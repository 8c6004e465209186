"""Serving requests: the path a request takes through the server.

- :mod:`~rlenv.serving._endpoint`: sockets (clients, the controller, limits, deadlines, token);
- :mod:`~rlenv.serving._host`: K instances answering as one server, by one door;
- :mod:`~rlenv.serving._parts`: one record per kind of request part (check, apply, control);
- :mod:`~rlenv.serving._instance`: one environment in its own tree, and its episode's state;
- :mod:`~rlenv.serving._columns`: the answer of a ``steps`` request, in columns;
- :mod:`~rlenv.serving._snapshots`: the episode as data, to restore anywhere;
- :mod:`~rlenv.serving._inspector`: the node tree and exported properties, remotely.

Nothing here is imported by ``rlenv_client`` unless an environment runs in its process.
"""
