"""The OpenMP wait policy the CLI sets before numba loads its threading layer."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from svgf_cli.openmp import wait_passively


def test_sets_passive_waiting_when_the_user_chose_nothing(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.delenv("OMP_WAIT_POLICY", raising=False)
    monkeypatch.delenv("GOMP_SPINCOUNT", raising=False)
    assert wait_passively()
    assert os.environ["OMP_WAIT_POLICY"] == "passive"


@pytest.mark.parametrize("name, value", [("OMP_WAIT_POLICY", "active"), ("GOMP_SPINCOUNT", "10")])
def test_the_users_own_setting_wins(monkeypatch: pytest.MonkeyPatch, name: str, value: str) -> None:
    monkeypatch.delenv("OMP_WAIT_POLICY", raising=False)
    monkeypatch.delenv("GOMP_SPINCOUNT", raising=False)
    monkeypatch.setenv(name, value)
    assert not wait_passively()
    assert os.environ[name] == value
    assert "OMP_WAIT_POLICY" not in os.environ or name == "OMP_WAIT_POLICY"


def test_the_cli_sets_it_before_any_command_runs(tmp_path: Path) -> None:
    # `svgf --version` goes through main(): the policy is in the environment by then.
    script = (
        "import os, sys\n"
        "from svgf_cli import cli\n"
        "try:\n"
        "    cli.main(['--version'])\n"
        "except SystemExit:\n"
        "    pass\n"
        "sys.stderr.write(os.environ.get('OMP_WAIT_POLICY', 'unset'))\n"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT")}
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          env=env, cwd=tmp_path, check=True)
    assert done.stderr.strip().endswith("passive")
