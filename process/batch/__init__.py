"""`semreplay-process batch`: many recordings, one task each, on a local process pool or Ray.

`runner.run_batch` is the entry point; `tasks` is what one task does (shared by both
executors), `local` and `ray_exec` run the tasks, `summary` and `report` write the results.
"""
