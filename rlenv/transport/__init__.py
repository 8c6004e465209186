"""The I/O both ends share, beside the sans-IO protocol (:mod:`rlenv.protocol`).

- :mod:`~rlenv.transport.sockets`: the socket options both ends set (kernel timeouts,
  ``TCP_NODELAY``), and how a process waits for the other end's next bytes (a bounded spin
  that gives its core away when another process wants it, then a blocking read);
- :mod:`~rlenv.transport.lanes`: a shared-memory lane's block and doorbell (setting it up,
  ringing, waiting on the lane and its socket together); which requests fit its slots is
  :mod:`rlenv.protocol.shared_memory`'s business;
- :mod:`~rlenv.transport.frames`: one whole frame from a blocking socket, for simple peers;
- :mod:`~rlenv.transport._procfs`: what one process reads of another in ``/proc`` (the one reader).

The server's endpoint (:mod:`rlenv.serving._endpoint`) and the TCP client
(``rlenv_client.client``) use both. Importing this package loads neither the runtime nor pymunk.
"""
