"""`python -m capture`: the semreplay-capture command line."""

from __future__ import annotations

from capture.cli import app

app(prog_name="semreplay-capture")
