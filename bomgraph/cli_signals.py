"""How a ``bomgraph`` command is stopped from outside: SIGINT and SIGTERM (their handlers,
:class:`Terminated`, the exit statuses 130 and 143, a signal whose exception Python dropped in
a finaliser delivered again) and a closed pipe on stdout (status 141). :func:`bomgraph.cli.main`
installs the handlers around each command (:func:`own_signals`) and restores the caller's
after it.
"""

from __future__ import annotations

import os
import signal
import sys
from typing import Any, Callable

#: the signals that stop a command (:func:`_on_signal`).
_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM") if hasattr(signal, n))


class Terminated(SystemExit):
    """SIGTERM, raised in the main thread: unwinds (so partial files are removed) and exits
    with status 143."""


def _on_signal(signum: int, frame: Any) -> None:
    """SIGINT raises KeyboardInterrupt, SIGTERM :class:`Terminated`; a later SIGINT or
    SIGTERM is ignored, as the command is stopping already: raised in the middle of the
    cleanup of the first (an ``except`` or ``finally`` block), it would stop that cleanup or
    end in a traceback."""
    for s in _SIGNALS:
        signal.signal(s, signal.SIG_IGN)
    if signum == signal.SIGINT:
        raise KeyboardInterrupt
    raise Terminated(128 + signum)


def _on_unraisable(unraisable: Any, previous: Callable[[Any], None],
                   signals: tuple[int, ...] = _SIGNALS) -> None:
    """``sys.unraisablehook``: a SIGINT or SIGTERM whose exception was raised inside a
    ``__del__`` or a finaliser (a generator closed by the garbage collector, say) is dropped
    by Python after printing "Exception ignored in ...", and the command would carry on with
    the signals ignored; it is delivered again instead, a moment later, by another thread, so
    that it is raised in the main thread's own code."""
    exc = unraisable.exc_value
    if not isinstance(exc, (KeyboardInterrupt, Terminated)):
        previous(unraisable)
        return
    import _thread
    import threading

    signum = signal.SIGINT if isinstance(exc, KeyboardInterrupt) else signal.SIGTERM
    for s in signals:   # those the command handles (not one ignored when it started)
        signal.signal(s, _on_signal)
    try:
        threading.Timer(0.01, _thread.interrupt_main, (signum,)).start()
    except RuntimeError:  # the interpreter is shutting down: the command has ended
        pass


def stopped(exc: BaseException) -> str:
    return "terminated" if isinstance(exc, Terminated) else "interrupted"


def stop_status(exc: BaseException) -> int:
    return 128 + (signal.SIGTERM if isinstance(exc, Terminated) else signal.SIGINT)


def forget_unhandled_interrupt() -> None:
    """Under ``python -m bomgraph``, a KeyboardInterrupt that came out of code run from a
    string (the functions ``dataclasses`` and ``namedtuple`` make, in an import) leaves a
    flag in CPython that makes the process kill itself with SIGINT at exit, once the
    interrupt has been handled and the status set (status -2, not 130). Running any string
    clears that flag."""
    exec("None")


def stdout_closed() -> int:
    """A closed pipe on stdout (``bomgraph methods | head -1``): exit quietly."""
    try:  # stop the interpreter's final flush from failing again on the closed pipe
        with open(os.devnull, "wb") as null:  # closed after: none left open (h86)
            os.dup2(null.fileno(), sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):  # AttributeError: closed (>&-, h86)
        pass
    return 128 + signal.SIGPIPE if hasattr(signal, "SIGPIPE") else 1


def own_signals(hook: Callable[[Any], None]) -> dict[int, Any]:
    """Install :func:`_on_signal` for SIGINT and SIGTERM and :func:`_on_unraisable` before
    ``hook`` (main thread only); the signal handlers it replaced."""
    import functools
    import threading

    if threading.current_thread() is not threading.main_thread():
        return {}
    # a signal ignored when the command started (a background job of a non-interactive
    # shell ignores SIGINT, so a Ctrl-C at the terminal is not its) stays ignored
    previous = {s: signal.signal(s, _on_signal) for s in _SIGNALS
                if signal.getsignal(s) is not signal.SIG_IGN}
    sys.unraisablehook = functools.partial(_on_unraisable, previous=hook,
                                           signals=tuple(previous))
    return previous


__all__ = ["Terminated", "own_signals", "stopped", "stop_status", "forget_unhandled_interrupt",
           "stdout_closed"]
