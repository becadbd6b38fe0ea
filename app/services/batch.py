"""Batch executor: run independent tasks (simulate a section, evaluate a section, one
optimiser candidate) on a local process pool or on a Dask distributed cluster.

* default: ``concurrent.futures.ProcessPoolExecutor`` with 2 workers (the 2-core machines of
  the deployment), started with the ``forkserver`` method so it is safe to use from the
  Panel app's background threads; its workers end when the process that started them ends
  (:mod:`railval.core.workers`), even when it is killed;
* ``scheduler="serial"`` (or ``workers=1``): in the calling process, no pickling — for
  debugging and for tiny jobs;
* ``scheduler="tcp://host:8786"``: a ``dask.distributed.Client`` connected to that scheduler
  (``deploy/`` starts one); tasks must be importable top-level functions with picklable
  arguments, exactly as for the process pool.

Results come back in task order and are identical whichever back end ran them (the test
``tests/test_batch_dask.py`` checks this against a real ``LocalCluster``). An executor is a
context manager and can be reused for many ``map`` calls (the calibration optimiser maps one
generation at a time); its ``map`` has the ``map(func, iterable)`` signature that
``scipy.optimize.differential_evolution(workers=...)`` accepts.

``map(func, items, shared=obj)`` calls ``func(obj, item)``: ``obj`` (a campaign context of
≈ 1 MB) travels once per worker, not once per task — the process pool's workers receive it
with their start (a new pool when another object is shared), a Dask cluster gets it by
``Client.scatter(..., broadcast=True)``. The process pool forks the workers when the calling
thread is the main thread and no other thread than railval's own idle row threads runs (the
CLI, the bench): the workers start with the caller's imported modules and compiled kernels
instead of importing them again (measured in docs/diagnosis.md "Diagnosis speed"); from the
Panel app's background threads it uses ``forkserver``.
"""

from __future__ import annotations

import multiprocessing
import os
import threading
import uuid
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any, Self

from railval.core import lazy
from railval.core.errors import InvalidParameter
from railval.core.workers import pool_kwargs

#: deferred (railval.core.lazy): dask.distributed (a Dask client, ~530 modules) only for a
#: map with a scheduler
distributed = lazy.module("dask.distributed")
#: deferred: the forkserver's module (POSIX), for :func:`start_forkserver`
forkserver = lazy.module("multiprocessing.forkserver")

DEFAULT_WORKERS = 2

Progress = Callable[[int, int], None]


class BatchExecutor:
    """Map a function over items on the chosen back end.

    Parameters
    ----------
    scheduler : None (local process pool), ``"serial"``, or a Dask scheduler address
        (``"tcp://…"``, ``"host:port"``) — also accepts an existing ``dask.distributed.Client``.
    workers : process-pool size (default 2; ``$RAILVAL_WORKERS`` overrides); 1 → serial.
    """

    def __init__(self, scheduler: Any = None, workers: int | None = None):
        if workers is None:
            workers = int(os.environ.get("RAILVAL_WORKERS", DEFAULT_WORKERS))
        if workers < 1:
            raise InvalidParameter(f"workers must be ≥ 1, got {workers}")
        self.workers = workers
        self._client = None
        self._own_client = False
        self._pool: ProcessPoolExecutor | None = None
        self._pool_token: str | None = None
        self._shared: tuple[Any, Any] | None = None  # (object, its token / Dask future)
        if scheduler is None:
            self.backend = "serial" if workers == 1 else "process"
        elif isinstance(scheduler, str) and scheduler.lower() in ("serial", "local-serial"):
            self.backend = "serial"
        elif isinstance(scheduler, str) and scheduler.lower() in ("process", "local"):
            self.backend = "serial" if workers == 1 else "process"
        else:
            self.backend = "dask"
            self._scheduler = scheduler

    # -- lifecycle
    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
        if self._client is not None and self._own_client:
            self._client.close()
        self._client = None

    def _dask_client(self):
        if self._client is None:
            try:
                Client = distributed.Client
            except ImportError as exc:  # pragma: no cover - dask is a declared extra
                raise InvalidParameter(
                    f"--scheduler {self._scheduler!r} needs dask.distributed (pip install 'railval[dask]')"
                ) from exc
            if isinstance(self._scheduler, Client):
                self._client = self._scheduler
            else:
                try:
                    self._client = Client(self._scheduler, timeout="10s")
                except OSError as exc:
                    raise InvalidParameter(
                        f"cannot reach the Dask scheduler at --scheduler {self._scheduler!r}: {exc}") from exc
                self._own_client = True
        return self._client

    def _process_pool(self, token: str | None = None, shared: Any = None) -> ProcessPoolExecutor:
        """The pool; a new one whose workers hold ``shared`` under ``token`` when they do not yet."""
        if self._pool is not None and token is not None and token != self._pool_token:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
        if self._pool is None:
            kw = pool_kwargs()
            if token is not None:
                kw = {"initializer": _init_worker, "initargs": (kw, token, shared)}
            self._pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=start_context(), **kw)
            self._pool_token = token
        return self._pool

    def _token(self, shared: Any) -> Any:
        """The token (process pool) or scattered future (Dask) of ``shared``, made once per object."""
        if self._shared is None or self._shared[0] is not shared:
            if self.backend == "dask":
                ref = self._dask_client().scatter(shared, broadcast=True, hash=False)
            else:
                ref = uuid.uuid4().hex
            self._shared = (shared, ref)
        return self._shared[1]

    def broadcast(self, obj: Any) -> Any:
        """``obj`` made ready for several tasks' arguments: on Dask scattered once to the workers
        (``Client.scatter(broadcast=True)``; a worker lacking it fetches it from another; a task's
        argument holding the future receives the object) instead of travelling inside each task's
        description through the scheduler; the object itself on the other back ends (a pool
        pickles it with each task)."""
        if self.backend != "dask":
            return obj
        return self._dask_client().scatter(obj, broadcast=True, hash=False)

    # -- work
    def start(self, shared: Any = None) -> None:
        """Start the workers now, in the calling thread, holding ``shared`` for later
        :meth:`map` calls — also from other threads: a worker's parent-death signal
        (:mod:`railval.core.workers`) follows the thread that started it, so a pool launched
        by a thread that ends would lose its workers; and from the main thread the pool forks
        (:func:`start_context`)."""
        if self.backend == "process":
            pool = self._process_pool(*((self._token(shared), shared) if shared is not None else ()))
            list(pool.map(_noop, range(self.workers)))
        elif self.backend == "dask" and shared is not None:
            self._token(shared)

    def submit(self, func: Callable[..., Any], items: Iterable[Any], *, shared: Any = None) -> list[Any]:
        """Hand ``func`` of every item to the back end now, without waiting (with ``shared``:
        ``func(shared, item)``, ``shared`` sent once per worker); one handle per item, for
        :meth:`gather`. The workers take the items in this order, after those handed over
        before. Serial: each item runs when it is first gathered."""
        items = list(items)
        if self.backend == "serial":
            return [_Deferred(func, item, shared) for item in items]
        if self.backend == "process":
            if shared is None:
                pool = self._process_pool()
                return [pool.submit(func, item) for item in items]
            token = self._token(shared)
            pool = self._process_pool(token, shared)
            return [pool.submit(_with_shared, token, func, item) for item in items]
        client = self._dask_client()
        if shared is None:
            return list(client.map(func, items, pure=False))
        return list(client.map(_apply_shared, items, task=func, shared=self._token(shared), pure=False))

    def gather(self, handles: Sequence[Any], progress: Progress | None = None) -> list[Any]:
        """The results of :meth:`submit`'s ``handles``, in their order; ``progress(done, total)``
        after every finished one, in the calling thread. Several threads may gather the same
        handles (the waiting is the futures' own)."""
        total = len(handles)
        if not total:
            return []
        if self.backend == "serial" or progress is None:
            out = []
            for k, h in enumerate(handles, start=1):
                out.append(h.result())
                if progress:
                    progress(k, total)
            return out
        where = {h: k for k, h in enumerate(handles)}
        done_iter = as_completed(where) if self.backend == "process" else distributed.as_completed(list(where))
        results: list[Any] = [None] * total
        for done, fut in enumerate(done_iter, start=1):
            results[where[fut]] = fut.result()
            progress(done, total)
        return results

    def map(self, func: Callable[..., Any], items: Iterable[Any], progress: Progress | None = None,
            *, shared: Any = None) -> list[Any]:
        """``[func(item) for item in items]`` on the back end, in order (with ``shared``:
        ``func(shared, item)``, ``shared`` sent once per worker). ``progress(done, total)``
        is called in the calling thread after every finished task."""
        items = list(items)
        if len(items) == 1 and self.backend == "process":
            items = [func(items[0]) if shared is None else func(shared, items[0])]
            if progress:
                progress(1, 1)
            return items
        return self.gather(self.submit(func, items, shared=shared), progress)

    # scipy's differential_evolution calls workers(func, iterable)
    __call__ = map


#: modules the forkserver imports once for the workers it starts (``__main__`` as by default);
#: the last runs one short campaign run, so the workers start with the compiled kernels loaded
#: (:mod:`railval.app.services.forkserver_warm`)
FORKSERVER_PRELOAD = ("__main__", "railval.core.sim.model", "railval.core.en14363",
                      "railval.app.services.diagnosis_ranking", "railval.app.services.campaign_context",
                      "railval.app.services.forkserver_warm")

#: objects shared with this worker process by :meth:`BatchExecutor.map` (token → object)
_SHARED: dict[str, Any] = {}


def _init_worker(base: dict[str, Any], token: str, shared: Any) -> None:
    """Process-pool initializer: the usual one (:func:`railval.core.workers.pool_kwargs`), then
    keep the shared object of this pool."""
    base["initializer"](*base["initargs"])
    _SHARED.clear()
    _SHARED[token] = shared


def _noop(item: Any) -> Any:
    return item


class _Deferred:
    """A serial back end's handle (:meth:`BatchExecutor.submit`): ``func`` of the item, run
    once, when its result is first asked for."""

    def __init__(self, func: Callable[..., Any], item: Any, shared: Any):
        self._call = (func, item, shared)
        self._done = False
        self._value: Any = None

    def result(self) -> Any:
        if not self._done:
            func, item, shared = self._call
            self._value = func(item) if shared is None else func(shared, item)
            self._done, self._call = True, None
        return self._value


def _with_shared(token: str, func: Callable[..., Any], item: Any) -> Any:
    return func(_SHARED[token], item)


def _apply_shared(item: Any, task: Callable[..., Any], shared: Any) -> Any:
    return task(shared, item)


def start_context() -> Any:
    """``fork`` when the calling thread is the main thread and every other thread is one of
    railval's idle row threads (:func:`railval.core.workers.split_rows`, which forget their
    pool in a forked child): the workers start with this process's modules and compiled
    kernels; ``forkserver`` otherwise (the Panel app's background threads)."""
    others = [t for t in threading.enumerate() if t is not threading.current_thread()]
    quiet = threading.current_thread() is threading.main_thread() and all(
        t.name.startswith("railval-rows") for t in others)
    if quiet and "fork" in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("fork")
    ctx = multiprocessing.get_context("forkserver")
    # the forkserver imports the simulator, the EN chain and the diagnosis once; every worker it
    # forks then starts with them (takes effect when this process starts its forkserver)
    ctx.set_forkserver_preload(list(FORKSERVER_PRELOAD))
    return ctx


def start_forkserver(extra: Sequence[str] = (), after: Any = None) -> bool:
    """Start this process's ``forkserver`` with :data:`FORKSERVER_PRELOAD` and ``extra``
    modules, instead of when the first pool of a background thread needs it: ``railval serve``
    calls it once the demo is seeded, so the server's first diagnosis, calibration or
    workshop does not wait for the forkserver's imports and kernel warm-up (≈ 3 CPU-s).
    ``after``: a process to wait for first (the server's low-priority warm-up child,
    :mod:`railval.app.services.warmup`) — then a daemon thread starts the forkserver once it
    has ended and this call returns at once: on a fresh installation the child compiles the
    kernels at the lowest priority, and the forkserver, which runs at the server's, then only
    loads them instead of compiling them beside the server's first pages. A pool needing the
    forkserver before then starts it itself (the standard library serialises the two).
    Returns False where there is no forkserver (not POSIX)."""
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return False

    def start() -> None:
        if after is not None:
            after.wait()
        forkserver.set_forkserver_preload([*FORKSERVER_PRELOAD, *extra])
        forkserver.ensure_running()

    if after is None:
        start()
    else:
        threading.Thread(target=start, name="railval-forkserver-start", daemon=True).start()
    return True


def _call(task: tuple[Callable[..., Any], Sequence[Any], dict[str, Any]]) -> Any:
    func, args, kwargs = task
    return func(*args, **kwargs)


def run_tasks(tasks: Sequence[tuple[Callable[..., Any], Sequence[Any], dict[str, Any]]], *,
              scheduler: Any = None, workers: int | None = None, progress: Progress | None = None) -> list[Any]:
    """Run heterogeneous tasks ``(func, args, kwargs)`` and return their results in order.

    Example: ``run_tasks([(simulate_section, (vehicle, section), {"effects": e}) for ...])``.
    Functions must be importable top-level callables (pickled by reference).
    """
    with BatchExecutor(scheduler, workers) as ex:
        return ex.map(_call, list(tasks), progress=progress)
