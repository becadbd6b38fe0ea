"""Worker processes that end with the process that started them.

A process pool's workers (and the ``forkserver`` that forks them) outlive a parent that is
killed with SIGKILL: nothing tells them, and each keeps its memory (≈ 300 MB for a
simulation worker) until the machine restarts. :func:`pool_initializer` is passed as the
``initializer`` of every :class:`concurrent.futures.ProcessPoolExecutor` railval starts
(``initializer=exit_with_parent, initargs=(os.getpid(),)``); it makes the worker exit as
soon as that parent is gone:

* on Linux, ``prctl(PR_SET_PDEATHSIG, SIGKILL)`` (proc(5), prctl(2)) — the kernel kills the
  worker when its direct parent (the forkserver, or the main process under ``fork``) ends;
* everywhere, a daemon thread that checks every :data:`WATCH_INTERVAL_S` seconds whether
  the main process still exists (``os.kill(pid, 0)``) and ends the worker with
  ``os._exit`` when it does not — this covers a forkserver that outlives the main process.
"""

from __future__ import annotations

import contextvars
import os
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

#: seconds between two checks of the watch thread
WATCH_INTERVAL_S = 0.5
_PR_SET_PDEATHSIG = 1
_SIGKILL = 9


def _set_parent_death_signal() -> None:
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, _SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):  # not Linux: the watch thread alone does the job
        pass


#: glibc's mallopt(3) parameters: M_TRIM_THRESHOLD, M_MMAP_THRESHOLD
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
#: blocks below this size come from the heap, and the heap is not given back below this top
KEEP_HEAP_BYTES = 64 << 20


def keep_freed_memory() -> bool:
    """In a worker that allocates and frees the same large buffers for every task (a review
    plot's pixels, Up-filtered rows and PNG: ≈ 7 MB a plot): tell glibc's allocator
    (mallopt(3)) to serve blocks below :data:`KEEP_HEAP_BYTES` from the heap and not to
    give the heap's free top back to the kernel, so a freed buffer is reused instead of being
    unmapped and faulted in again, page by page, for the next task. Measured on the 120 demo
    review plots, two render workers (docs/workshops.md "Workers started before the signals
    are read"): minor page faults a worker 67 000–123 000 → 8 000–9 000, system time 0.19–0.31
    → 0.05–0.10 s, rendering 1.46–1.58 → 1.19–1.27 s. The heap then holds the worker's high
    mark until it ends. False (nothing changed) where the C library is not glibc."""
    try:
        import ctypes

        libc = ctypes.CDLL(None)
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # no glibc: the allocator keeps its own policy
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, KEEP_HEAP_BYTES)) and bool(
        mallopt(_M_TRIM_THRESHOLD, 4 * KEEP_HEAP_BYTES))


def process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else (pid reused): treat as gone
        return False
    return True


def _watch(pid: int) -> None:
    while True:
        if not process_alive(pid) or os.getppid() == 1:
            os._exit(1)
        time.sleep(WATCH_INTERVAL_S)


def exit_with_parent(parent_pid: int) -> None:
    """Worker initializer: end this process when ``parent_pid`` (the pool's owner) ends."""
    _set_parent_death_signal()
    if not process_alive(parent_pid):
        os._exit(1)
    threading.Thread(target=_watch, args=(parent_pid,), name="railval-exit-with-parent",
                     daemon=True).start()


def pool_kwargs() -> dict:
    """``initializer``/``initargs`` for a ProcessPoolExecutor started by this process."""
    return {"initializer": exit_with_parent, "initargs": (os.getpid(),)}


# -- threads for compiled kernels that release the GIL ------------------------------------

_THREAD_POOL = None
_THREAD_POOL_LOCK = threading.Lock()


def _forget_thread_pool() -> None:
    """In a forked child: the parent's pool threads do not exist there, so its pool must not
    be used (tasks would wait forever); the child makes its own on first use."""
    global _THREAD_POOL, _THREAD_POOL_LOCK
    _THREAD_POOL = None
    _THREAD_POOL_LOCK = threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_thread_pool)


#: row threads set by :func:`row_threads` for the work of this context (None: not set)
_ROW_THREADS: contextvars.ContextVar[int | None] = contextvars.ContextVar(
    "railval_row_threads", default=None)


@contextmanager
def row_threads(n: int) -> Iterator[None]:
    """Within the block (this thread and work it hands on with
    :func:`railval.core.stages.in_context`), :func:`thread_count` returns ``n``: a thread that
    processes one of several chunks at once takes its share of the cores instead of all."""
    token = _ROW_THREADS.set(max(1, int(n)))
    try:
        yield
    finally:
        _ROW_THREADS.reset(token)


def thread_count() -> int:
    """Threads for row-parallel compiled kernels: the :func:`row_threads` setting of this
    context, else ``$RAILVAL_THREADS`` if set (≥ 1), else the cores this process may run on
    (at most 8)."""
    override = _ROW_THREADS.get()
    return override if override is not None else _process_thread_count()


def _process_thread_count() -> int:
    env = os.environ.get("RAILVAL_THREADS", "").strip()
    if env:
        try:
            return max(1, int(env))
        except ValueError:
            pass
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        cores = os.cpu_count() or 1
    return max(1, min(cores, 8))


def split_rows(fn, n_rows: int, *, min_rows: int = 1, align: int = 1) -> None:
    """Run ``fn(start, stop)`` over contiguous parts of ``range(n_rows)`` on up to
    :func:`thread_count` threads, the caller's thread doing the last part; ``fn`` must release
    the GIL (a numba ``nogil`` kernel) for the parts to run at once. Parts hold at least
    ``min_rows`` rows and start at multiples of ``align``. Exceptions of a part propagate."""
    global _THREAD_POOL
    parts = min(thread_count(), max(1, n_rows // max(1, min_rows)))
    if parts <= 1:
        fn(0, n_rows)
        return
    step = -(-n_rows // parts)
    step = -(-step // align) * align
    bounds = [(a, min(a + step, n_rows)) for a in range(0, n_rows, step)]
    if len(bounds) == 1:
        fn(0, n_rows)
        return
    with _THREAD_POOL_LOCK:
        if _THREAD_POOL is None:
            from concurrent.futures import ThreadPoolExecutor

            _THREAD_POOL = ThreadPoolExecutor(max_workers=max(1, _process_thread_count() - 1),
                                              thread_name_prefix="railval-rows")
        pool = _THREAD_POOL
    futures = [pool.submit(fn, a, b) for a, b in bounds[:-1]]
    fn(*bounds[-1])
    for f in futures:
        f.result()
