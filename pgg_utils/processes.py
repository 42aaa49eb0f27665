"""Children that die with their parent, however it dies (Linux: the kernel's parent-death signal), and the
sweep's pool of such workers, which breaks when one dies."""

import ctypes
import multiprocessing
import os
import signal
import sys
from concurrent.futures import ProcessPoolExecutor

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


def init_worker(parent_pid: int) -> None:
    """Pool initializer: a worker leaves Ctrl-C to the parent (which ends the workers), and dies with
    the parent however the parent dies."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(
        signal.SIGTERM, signal.SIG_DFL
    )  # the pool's signal to end it, not a handler inherited from the parent
    die_with_parent(parent_pid)


def start_pool(workers: int, run, jobs: list) -> tuple[ProcessPoolExecutor, dict, dict]:
    """(the pool, {future: job} of `run(job)` for every job, {pid: process} of its workers). Forked
    workers are all started by the first submit, from this thread (their death signal is tied to the
    thread that forks them). Unlike multiprocessing.Pool, which replaces a worker that dies and waits
    forever for the job it held, this pool breaks: every unfinished job fails with BrokenProcessPool."""
    pool = ProcessPoolExecutor(workers, multiprocessing.get_context("fork"), init_worker, (os.getpid(),))
    try:
        pool.submit(os.getpid)  # starts the workers; they are counted before any can die in a cell
        processes = {p.pid: p for p in multiprocessing.active_children()}
        return pool, {pool.submit(run, job): job for job in jobs}, processes
    except BaseException:  # Ctrl-C while starting: the caller holds no pool yet to stop
        stop_pool(pool, {p.pid: p for p in multiprocessing.active_children()})
        raise


def stop_pool(pool: ProcessPoolExecutor, processes: dict) -> None:
    """Ends the workers now, their jobs in flight lost (Ctrl-C, a pool broken by a dead worker, or the
    caller's end), then the pool, waiting for its manager thread. That thread must be gone before the
    interpreter exits: Python 3.11's exit hook (concurrent.futures.process._python_exit) writes to the
    thread's wakeup pipe without the lock under which the thread closes it, so a thread still closing its
    pipe at exit makes that write fail ("Exception ignored ... OSError: [Errno 9] Bad file descriptor")."""
    for process in processes.values():
        process.terminate()  # SIGTERM, which how_workers_died tells from any other end
    for process in processes.values():
        process.join()
    pool.shutdown(wait=True, cancel_futures=True)  # the workers are gone: the manager thread ends at once


def how_workers_died(processes: dict) -> str:
    """`pid 123 was killed by SIGKILL`: the workers that ended before the pool ended them (with SIGTERM)."""
    ended = [(pid, p.exitcode) for pid, p in processes.items() if p.exitcode not in (None, -signal.SIGTERM)]
    return ", ".join(f"pid {pid} " + (f"was killed by {signal.Signals(-code).name}" if code < 0
                                      else f"exited with status {code}") for pid, code in ended) or "a worker ended"  # fmt: skip
