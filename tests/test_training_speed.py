"""``rlenv bench --train``: trainers' patterns against the environment in process."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from rlenv_tools.training_speed import format_rows, measure_training, resolve_target, rows_to_json


def test_sync_vectors_are_measured_against_one_env_and_in_process() -> None:
    rows = measure_training("rlenv/CartPole-v1", rounds=2, steps=400, ppo=False)
    against_one = [row for row in rows if row.group.endswith("against one env")]
    against_local = [row for row in rows if row.group.endswith("against in process")]
    assert [row.name for row in against_one] == [f"SyncVectorEnv({k})" for k in (1, 2, 4, 8, 16)]
    assert against_one[0].ratio == against_one[0].ratio_min == 1.0  # its own baseline
    assert [row.baseline for row in against_local] == [
        f"SyncVectorEnv({k}) in process" for k in (1, 2, 4, 8, 16)
    ]
    for row in rows:
        assert row.rate > 0 and 0 < row.ratio_min <= row.ratio
    table = format_rows(rows)
    assert "| SyncVectorEnv(8) |" in table and "ratio (median)" in table
    assert json.loads(rows_to_json(rows))[0]["name"] == "SyncVectorEnv(1)"


def test_a_target_is_a_registered_id_or_module_class() -> None:
    assert resolve_target("rlenv/CartPole-v1") == (
        "rlenv.examples.classic_cartpole:ClassicCartPoleEnvironment",
        500,
    )
    assert resolve_target("examples.pair:PairEnvironment") == (
        "examples.pair:PairEnvironment",
        None,
    )
    with pytest.raises(ValueError, match="expected MODULE:CLASS or a registered id"):
        resolve_target("CartPole")


def test_the_command_says_in_one_line_what_it_cannot_measure() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "rlenv", "bench", "--train", "CartPole"],
        capture_output=True,
        text=True,
        timeout=60,
        stdin=subprocess.DEVNULL,
    )
    assert result.returncode == 2
    assert result.stderr.startswith("rlenv bench: expected MODULE:CLASS or a registered id")
