"""Shared test fixtures: where the real recordings live, and how to treat their absence."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def shared_data_dir(name: str) -> Path:
    """``../shared/data/<name>``; skip when absent, but fail under CI (``CI`` set)."""
    path = DATA / name
    if not path.is_dir():
        reason = f"real recordings not found at {path} (clone ../shared beside the project)"
        if os.environ.get("CI"):
            pytest.fail(reason)
        pytest.skip(reason)
    return path


@pytest.fixture
def shared_data():
    """Call ``shared_data("sap6")`` for the folder of one recording set."""
    return shared_data_dir


@pytest.fixture(autouse=True)
def _work_in_a_temporary_folder(tmp_path, monkeypatch):
    """Every test runs in its own empty folder: a command's default output (``cal.json``) never
    lands in the checkout, and no test sees another's."""
    monkeypatch.chdir(tmp_path)


# Property tests are part of CI: draw the same examples on every run.
# The autouse temporary folder is shared by a property test's examples, which is what we want.
settings.register_profile(
    "fieldcal",
    derandomize=True,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
settings.load_profile("fieldcal")
