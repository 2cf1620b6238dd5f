"""The command line, ``kindyngen --help`` (also ``python -m kindyngen``)."""
import signal

from .interrupts import ending_on_signals


def command_line() -> int:
    """The ``kindyngen`` command (the console script and ``python -m kindyngen``): the command
    line's :func:`~kindyngen.cli.main.main`, with an interrupt while its modules are still being
    imported ending the same way."""
    def run():
        from .main import main
        return main()
    code = ending_on_signals(run)
    # done: a signal while the interpreter shuts down (tens of ms) would only add a traceback
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, signal.SIG_IGN)
    return code
