"""The compiled kernels' OpenMP threads wait passively (benchmarks/results/stalls.md): set on
import unless the user chose otherwise."""

from __future__ import annotations

import os
import subprocess
import sys


def policy_after_import(env_policy: str | None) -> str:
    env = {key: value for key, value in os.environ.items() if key != "OMP_WAIT_POLICY"}
    if env_policy is not None:
        env["OMP_WAIT_POLICY"] = env_policy
    code = "import os, shadeform; print(os.environ['OMP_WAIT_POLICY'])"
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True
    ).stdout.strip()


def test_passive_by_default_and_the_user_s_choice_kept():
    assert policy_after_import(None) == "PASSIVE"
    assert policy_after_import("ACTIVE") == "ACTIVE"
