"""Ctrl-C (SIGINT) and SIGTERM end a command with one line on standard error, ``interrupted``
or ``terminated``, and exit code 130 or 143 (128 + the signal's number, as a shell reports a
process killed by it); never a traceback. Output folders are swapped in whole
(:mod:`kindyngen.output_folder`), so an interrupted command leaves the previous output, or the
new one complete when the signal came during the swap.

Python turns SIGINT into ``KeyboardInterrupt`` by itself; SIGTERM, which would kill the
process on the spot and leave a staging folder behind, is turned into :class:`Terminated`
here, so that it unwinds the same way (staging folders removed on the way out).

Example:

>>> def long_job():
...     raise KeyboardInterrupt
>>> ending_on_signals(long_job)
130
"""
from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from typing import Callable

EXIT_INTERRUPTED = 128 + signal.SIGINT       # 130
EXIT_TERMINATED = 128 + signal.SIGTERM       # 143
#: a signal swallowed by the garbage collector is sent again this much later (the collector's
#: callback has returned by then; the program ends within it, not after its work)
RESEND_DELAY_S = 0.05


class Terminated(BaseException):
    """SIGTERM, raised in the main thread as Python raises KeyboardInterrupt for SIGINT."""


def _raise_terminated(signum, frame):
    raise Terminated()


@contextlib.contextmanager
def sigterm_raises():
    """Inside the block (main thread only) SIGTERM raises :class:`Terminated`."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous if previous is not None else signal.SIG_DFL)


#: the signals swallowed (and sent again) during the current command: one that the command's
#: end outran still ends it as interrupted or terminated
_swallowed: list = []


@contextlib.contextmanager
def signals_not_swallowed():
    """Inside the block, a KeyboardInterrupt or :class:`Terminated` raised where Python cannot
    propagate it (a weakref callback or ``__del__`` run by the garbage collector: Python prints
    "Exception ignored in ..." with a traceback and carries on) is sent again as its signal, so
    it reaches the main program at the next bytecode instead of being lost (a SIGTERM landing in
    the collector once let a run finish after printing a traceback)."""
    previous = sys.unraisablehook
    _swallowed.clear()

    def hook(unraisable):
        # sent from another thread a moment later: signal.raise_signal and os.kill of the own
        # process run the handler at once, inside this hook, where it would be swallowed again
        for kind, signum in ((KeyboardInterrupt, signal.SIGINT), (Terminated, signal.SIGTERM)):
            if isinstance(unraisable.exc_value, kind):
                resend = threading.Timer(RESEND_DELAY_S, os.kill, (os.getpid(), signum))
                resend.daemon = True
                _swallowed.append((kind, resend))
                resend.start()
                return
        previous(unraisable)
    sys.unraisablehook = hook
    try:
        yield
    finally:
        sys.unraisablehook = previous
        for _, resend in _swallowed:     # not sent after the handlers are gone (it would kill)
            resend.cancel()


def _say(word: str) -> None:
    stream = sys.stderr
    with contextlib.suppress(Exception):          # a closed or broken standard error: the exit code says it
        # a progress line redrawn in place on a terminal has no newline yet
        stream.write(("\n" if stream.isatty() else "") + word + "\n")
        stream.flush()


def ending_on_signals(run: Callable[[], int]) -> int:
    """``run()``'s exit code, or 130 after one ``interrupted`` line (SIGINT) or 143 after one
    ``terminated`` line (SIGTERM) on standard error."""
    try:
        with sigterm_raises(), signals_not_swallowed():
            code = run()
            if _swallowed:
                raise _swallowed[-1][0]()
            return code
    except KeyboardInterrupt:
        _say("interrupted")
        return EXIT_INTERRUPTED
    except Terminated:
        _say("terminated")
        return EXIT_TERMINATED
