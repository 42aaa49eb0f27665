"""Ctrl-C while an entry script is still starting (importing torch and gymnasium, checking its
arguments: its first second or two) ends it with one line and status 130, as a later Ctrl-C does, not
with a traceback from inside an import. Every entry script imports this module before anything else;
it acts only where a script of this repository is the main program (not in a test that imports one),
and `ctrl_c_handled` hands Ctrl-C back to Python where the script starts catching it itself."""

import signal
import sys
import threading
from pathlib import Path


def interrupted_while_starting(signum, frame) -> None:
    print("interrupted while starting", file=sys.stderr)
    sys.exit(130)


def ctrl_c_handled() -> None:
    """From here on the script catches KeyboardInterrupt itself."""
    if signal.getsignal(signal.SIGINT) is interrupted_while_starting:
        signal.signal(signal.SIGINT, signal.default_int_handler)


MAIN_FILE = getattr(sys.modules.get("__main__"), "__file__", None)
if (
    MAIN_FILE is not None
    and Path(MAIN_FILE).resolve().parent == Path(__file__).resolve().parent.parent
    and threading.current_thread() is threading.main_thread()
    and signal.getsignal(signal.SIGINT) is signal.default_int_handler  # not where SIGINT is ignored
):
    signal.signal(signal.SIGINT, interrupted_while_starting)
