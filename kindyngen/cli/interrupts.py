"""Ctrl-C (SIGINT) and SIGTERM end a command with one line on standard error, ``interrupted``
or ``terminated``, and exit code 130 or 143 (128 + the signal's number, as a shell reports a
process killed by it); never a traceback. Output folders are swapped in whole
(:mod:`kindyngen.output_folder`), so an interrupted command leaves the previous output, or the
new one complete when the signal came during the swap.

Python turns SIGINT into ``KeyboardInterrupt`` by itself; SIGTERM, which would kill the
process on the spot and leave a staging folder behind, is turned into :class:`Terminated`
here, so that it unwinds the same way (staging folders removed on the way out).

Python runs those handlers between bytecodes only: a main thread inside one long C call (a
symengine CSE of a large robot's derivatives, minutes) would not see a Ctrl-C until the call
returns. A watcher thread (:func:`stuck_main_thread_ends`) learns of the signal through
Python's wakeup file descriptor; when no handler has run by STUCK_GRACE_S, it
says the line and ends the process with the same exit code (nothing is unwound then; a
staging folder of a write under way is removed by the next run, kindyngen.output_folder).

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
#: how long the main thread may stay in the one C call it was in when a signal came before the
#: watcher ends the process (a Python-level handler runs within microseconds otherwise)
STUCK_GRACE_S = 3.0


class Terminated(BaseException):
    """SIGTERM, raised in the main thread as Python raises KeyboardInterrupt for SIGINT."""


#: set by the handlers below when Python acts on a signal: the watcher then leaves it to them
_acted = threading.Event()
#: one ``interrupted`` / ``terminated`` line, whichever thread says it
_said = threading.Lock()


def _raise_terminated(signum, frame):
    _acted.set()
    raise Terminated()


def _raise_interrupt(signum, frame):
    _acted.set()
    raise KeyboardInterrupt


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
                _acted.set()            # a handler ran (inside a finaliser): the resend follows
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


def _forget_wakeup_fd() -> None:
    """In a forked child (identify's workers): its signals are its own, not the watcher's."""
    with contextlib.suppress(ValueError):
        signal.set_wakeup_fd(-1)


os.register_at_fork(after_in_child=_forget_wakeup_fd)


@contextlib.contextmanager
def stuck_main_thread_ends():
    """Inside the block (main thread only), a SIGINT or SIGTERM no handler acts on within
    STUCK_GRACE_S, because the main thread is inside one C call all that time, ends the process:
    ``interrupted`` or ``terminated`` and exit code 130 or 143 (see the module's text)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    read_fd, write_fd = os.pipe()
    os.set_blocking(write_fd, False)
    previous_fd = signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
    done = threading.Event()
    _acted.clear()
    previous_int = signal.getsignal(signal.SIGINT)
    if previous_int is signal.default_int_handler:     # the same, telling the watcher it ran
        signal.signal(signal.SIGINT, _raise_interrupt)

    def watch():
        while True:
            try:
                received = os.read(read_fd, 64)
            except OSError:
                return
            if not received or done.is_set():
                return
            for signum in dict.fromkeys(received):
                if signum not in (signal.SIGINT, signal.SIGTERM):
                    continue
                if done.wait(STUCK_GRACE_S):
                    return
                if not _acted.is_set():         # no handler ran: the main thread is inside one C call
                    _say("interrupted" if signum == signal.SIGINT else "terminated")
                    os._exit(128 + signum)

    watcher = threading.Thread(target=watch, name="kindyngen-signal-watcher", daemon=True)
    watcher.start()
    try:
        yield
    finally:
        done.set()
        if signal.getsignal(signal.SIGINT) is _raise_interrupt:
            signal.signal(signal.SIGINT, previous_int)
        signal.set_wakeup_fd(previous_fd)
        os.close(write_fd)              # the watcher reads the end of the pipe and returns
        watcher.join(timeout=1.0)
        os.close(read_fd)


def _say(word: str) -> None:
    if not _said.acquire(blocking=False):         # said already, by the other thread
        return
    stream = sys.stderr
    with contextlib.suppress(Exception):          # a closed or broken standard error: the exit code says it
        # a progress line redrawn in place on a terminal has no newline yet
        stream.write(("\n" if stream.isatty() else "") + word + "\n")
        stream.flush()


def ending_on_signals(run: Callable[[], int]) -> int:
    """``run()``'s exit code, or 130 after one ``interrupted`` line (SIGINT) or 143 after one
    ``terminated`` line (SIGTERM) on standard error."""
    if _said.locked():              # a command before this one (in this process) said its line
        _said.release()
    try:
        with sigterm_raises(), signals_not_swallowed(), stuck_main_thread_ends():
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
