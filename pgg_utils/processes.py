"""Children that die with their parent, however it dies (Linux: the kernel's parent-death signal)."""

import ctypes
import os
import signal
import sys

PR_SET_PDEATHSIG = 1
LIBC = ctypes.CDLL(None, use_errno=True) if sys.platform.startswith("linux") else None  # loaded now, not after fork


def die_with_parent(parent_pid: int) -> None:
    """Asks the kernel to kill this process when its parent ends; exits at once if the
    parent is already gone. Only an async-signal-safe system call and getppid run, so it is safe
    between fork and exec (a `preexec_fn`). Elsewhere than Linux it does nothing."""
    if LIBC is not None:
        LIBC.prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        if os.getppid() != parent_pid:
            os._exit(1)


def child_of(parent_pid: int):
    """A `preexec_fn` for subprocess.Popen: the child dies with `parent_pid` (see die_with_parent)."""
    return lambda: die_with_parent(parent_pid)
