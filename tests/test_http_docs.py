"""docs/http.md's client, run as it is written against a real gateway."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

from http_gateway import Gateway

DOCS = Path(__file__).resolve().parent.parent / "docs" / "http.md"


def test_the_documented_client_balances_cartpole(tmp_path: Path) -> None:
    text = DOCS.read_text()
    block = re.search(
        r"<!-- client: begin -->\n```python\n(.*?)```\n<!-- client: end -->", text, re.S
    )
    assert block is not None, "docs/http.md lost its client"
    code = block.group(1)
    assert len(code.strip().splitlines()) <= 32  # "a client in 30 lines"
    script = tmp_path / "client.py"
    script.write_text(code)
    gateway = Gateway("examples.cartpole:CartPoleEnvironment")
    try:
        result = subprocess.run(
            [sys.executable, str(script), gateway.url], capture_output=True, text=True, timeout=300
        )
        assert result.returncode == 0, result.stderr
        returns = [int(r) for r in re.findall(r"episode \d: return (\d+)", result.stdout)]
        assert len(returns) == 2 and min(returns) >= 400, result.stdout  # it balances
        assert gateway.get("/v1/envs")["envs"] == []  # and cleans up after itself
    finally:
        gateway.close()
