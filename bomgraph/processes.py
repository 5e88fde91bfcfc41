"""Tasks in local worker processes (joblib's loky executor: ``compare --jobs N``), started so
that a Ctrl-C stops the command alone.

A terminal's Ctrl-C reaches the whole process group: workers that took it printed their own
KeyboardInterrupt tracebacks (while they start, importing numpy; between tasks) beside the
command's one line. They start with SIGINT and SIGTERM blocked, which they keep, as do the
workers they start later (a worker replaced after a memory leak); the command stops on the
signal and ends them. Imports nothing from bomgraph but :mod:`bomgraph.stdio`.
"""

from __future__ import annotations

import warnings
from typing import Any, Callable, Iterator, Sequence

from .stdio import signals_held


def dispatch(func: Callable[[int, Any], tuple[int, dict[str, Any]]], index: Sequence[int],
             tasks: Sequence[Any], n_jobs: int) -> Iterator[tuple[int, dict[str, Any]]]:
    """``func(k, task)`` for each ``k`` of ``index`` and its task, in ``n_jobs`` worker
    processes (-1: one per core), as they finish. Closed early (the caller interrupted), the
    runs in flight are cancelled, without joblib's warning that they were."""
    from joblib import Parallel, delayed

    with Parallel(n_jobs=n_jobs, return_as="generator_unordered") as par:
        _start_workers(par)
        results = par(delayed(func)(k, t) for k, t in zip(index, tasks))
        try:
            for item in results:
                yield item
        except GeneratorExit:  # logging would print joblib's "N tasks ... were cancelled"
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)
                results.close()
            raise


def _start_workers(par: Any) -> None:
    """Start the workers of joblib's ``par`` (a loky executor; any other backend: nothing)
    with SIGINT and SIGTERM held (blocked): the mask is inherited, and a signal that comes
    meanwhile is this process's when the block ends."""
    from multiprocessing import resource_tracker

    workers = getattr(getattr(par, "_backend", None), "_workers", None)
    if callable(getattr(workers, "submit", None)):
        # first: Python 3.11 starts it with both unblocked after (SIG_UNBLOCK, not the mask
        # it found), which would undo the hold below
        resource_tracker.ensure_running()
        with signals_held():
            workers.submit(int)  # the first task starts the processes, in this thread


__all__ = ["dispatch"]
