"""The gateway reaches below uvicorn's public API only on the versions it was tested with."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

pytest.importorskip("uvicorn")

import uvicorn  # noqa: E402
from http_gateway import Gateway  # noqa: E402

from rlenv_tools.http import _uvicorn_protocol as uvicorn_protocol  # noqa: E402

CARTPOLE = "examples.cartpole:CartPoleEnvironment"


def test_the_installed_uvicorn_is_a_tested_one() -> None:
    low, high = uvicorn_protocol.TESTED
    assert low <= uvicorn_protocol._version(uvicorn.__version__) <= high
    protocol = uvicorn_protocol.http_protocol("h11", head_timeout=5.0, max_connections=8)
    assert protocol.__name__ == "BoundedOneWriteH11Protocol"
    assert uvicorn_protocol.connection_limit(8) is None  # the protocol bounds them itself


def test_another_uvicorn_serves_with_its_public_api_and_says_what_it_lacks(tmp_path: Path) -> None:
    (tmp_path / "sitecustomize.py").write_text(
        "import uvicorn\nuvicorn.__version__ = '0.99.0'  # as if another were installed\n"
    )
    path = os.pathsep.join([str(tmp_path), *filter(None, [os.environ.get("PYTHONPATH")])])
    gateway = Gateway(CARTPOLE, "--max-connections", "8", env={"PYTHONPATH": path})
    try:
        session = gateway.session()
        observation = gateway.post(f"/v1/envs/{session}/reset", {"seed": 3})["observation"]
        assert len(observation) == 5
        gateway.post(f"/v1/envs/{session}/step", {"action": [0.5]})
        said = gateway.stderr()
    finally:
        gateway.close()
    assert (
        "uvicorn 0.99.0 is not a version rlenv was tested with (0.30.0 to 0.54.0): "
        "responses take two writes, and request heads have no deadline"
    ) in said
