"""rlenv_tools: the tools above the runtime and the client, each both a client and a host.

- ``cli``: the ``rlenv`` command (``python -m rlenv`` too);
- ``http/``: the HTTP/JSON gateway (``rlenv http``);
- ``inspector/``, ``timeline``, ``forking``: the live inspector's page, timelines of an episode
  and the forked servers they branch from;
- ``compliance/``, ``_checks``, ``observations``: ``rlenv check``, a server held to the protocol;
- ``_bench``, ``training_speed``: ``rlenv bench``'s library code;
- ``datasets``, ``demonstrations``, ``policies``, ``_onnx_actors``: Minari datasets, recorded
  demonstrations, policies exported as ONNX files.

Layers (docs/architecture.md): the tools import the runtime (``rlenv``) and the client
(``rlenv_client``); neither of those imports the tools. Modules with a leading underscore are
not the public API (the docs' reference is).
"""

import rlenv  # noqa: F401  (its import keeps the old names of moved modules working)
