"""The batch tests' recordings: simulated once per session."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers_batch import write_recordings


@pytest.fixture(scope="session")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Return a folder of three small simulated recordings and one file that is not MCAP."""
    return write_recordings(tmp_path_factory.mktemp("recs"))
