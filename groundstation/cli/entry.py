"""The `groundstation` console script's entry point (pyproject.toml [project.scripts]).

Why not main.main directly: a log writer is a process started with multiprocessing's
"spawn", which runs the parent's main script again in the child, and the script pip
writes imports its entry point's module at the top.  With main.py there, every writer
(one per recording) imported the whole command line - every command group's parser -
before its own work: about 0.1-0.3 s of CPU each (docs/campaigns.md).  This module
imports nothing until the command runs - but first sets one BLAS thread for this process
and those it starts (core/blas_threads.py), which must happen before numpy loads."""

from __future__ import annotations


def main(argv: list[str] | None = None) -> int:
    from ..core.blas_threads import one_blas_thread

    one_blas_thread()
    from .main import main as run_command
    return run_command(argv)
