"""Shared fixtures: the repository, the command-line binary, and a fresh cache per test (tests
must see their own hits and misses, not another test's)."""

import os
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


def pytest_configure(config):
    config.addinivalue_line("markers", "slow: the slow tier, run by `scripts/test --all` (CI)")


@pytest.fixture(scope="session")
def repo() -> Path:
    return REPO


@pytest.fixture(scope="session")
def cli() -> Path:
    """The `mesoflow` binary of this checkout (built if missing: the README's test command
    builds it before the Python tests run)."""
    exe = Path(os.environ.get("MESOFLOW_BIN", REPO / "target" / "release" / "mesoflow"))
    if not exe.exists():
        subprocess.run(["cargo", "build", "--release", "--bin", "mesoflow"], cwd=REPO, check=True)
    return exe


@pytest.fixture
def cache(tmp_path: Path) -> Path:
    return tmp_path / "cache"


@pytest.fixture
def ctrl_c():
    """Python's own Ctrl-C handler for the test: a process started in the background by a
    non-interactive shell (`scripts/test &`, nohup) inherits SIGINT ignored, and Python then
    installs no handler, so the Ctrl-C tests would wait for an interrupt that never comes."""
    import signal

    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)
