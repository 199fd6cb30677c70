"""`python -m process` is `semreplay-process`."""

from process.cli import app

app(prog_name="semreplay-process")
