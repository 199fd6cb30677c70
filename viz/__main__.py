"""`python -m viz` is `semreplay-view`."""

from __future__ import annotations

from viz.cli import app

app(prog_name="semreplay-view")
