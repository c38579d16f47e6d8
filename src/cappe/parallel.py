"""Executors for the hot path: chunks of samples on threads, local processes or a Dask cluster.

numpy's batched LAPACK calls (``eigh``, ``cholesky``, ``inv``, stacked ``matmul``) release the GIL, so
threads over chunks of samples scale with the cores, while OpenBLAS's own threading gains little on small
matrices and can collapse when numpy and scipy calls interleave. Inside :func:`map_chunks` BLAS therefore
runs single-threaded and the parallelism is over samples. Every chunk computes each sample the same way,
so results do not depend on the chunk size, the number of workers or where the chunks run.

:class:`Executor` is the one place that decides where work runs:

- ``"serial"``: in the calling thread;
- ``"threads"``: a thread pool (the default; right where the work is batched numpy);
- ``"processes"``: local worker processes (right where pure-Python work holds the GIL); the function is
  shipped once per map with cloudpickle, so closures work;
- ``"tcp://HOST:PORT"`` (or any address ``dask.distributed.Client`` accepts): an existing Dask cluster; the
  function is scattered once to every worker, chunks run as tasks. ``dask-jobqueue`` (HPC batch systems) and
  ``dask-kubernetes`` clusters expose such an address too.

On Dask, objects of the types registered with :func:`ship_once` (cappe's compiled models and modal engines) travel
once per executor, not with every map: the function of a map is pickled with each such object replaced by a
reference, the object itself (its caches left behind) is scattered to every worker the first time a map needs it,
and each worker process unpickles it once and keeps it, with the caches it builds, until the executor closes. The
GSA of the three-axis machine maps once per position and chunk of samples, so its model and engine (2 MB, and 30 MB
more of caches per position) would otherwise be pickled, sent and unpickled a hundred times per worker.

Commands (``cappe ...``) run their whole work under :func:`command_blas_threads`: one BLAS thread unless the
environment variable ``CAPPE_BLAS_THREADS`` says otherwise (a number of threads, or ``auto`` for the BLAS
library's own choice). Their work is many small linear-algebra calls, which OpenBLAS's threads only slow down.

The first map also tunes glibc's allocator of this process to keep freed memory for reuse
(:func:`retain_freed_memory`; set a ``MALLOC_*_`` variable to keep glibc's defaults), and the first task of a Dask
map tunes its worker's: Dask's nanny starts workers with a 64 KiB trim threshold, which made their page faults
cost as much CPU as the work itself. A Dask task runs on the worker's executor thread, whose own malloc arena
unmaps its heaps whenever they empty, whatever the thresholds; only an environment set before the worker starts
helps there: start single-threaded workers with ``MALLOC_ARENA_MAX=1`` (20 modal-derivative evaluations of the
three-axis machine on a LocalCluster worker: 4.5 CPU-s and 329 000 page faults before, 3.1 CPU-s and 63 000 with
the tuning, 2.3 CPU-s and 215 with the one arena too, as in a plain process's main thread).
"""

from __future__ import annotations

import io
import os
import pickle
import sys
import threading
import uuid
import warnings
from collections import Counter, OrderedDict
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor, as_completed
from contextlib import contextmanager
from typing import Any, TypeVar

from threadpoolctl import ThreadpoolController

__all__ = [
    "BLAS_THREADS_VARIABLE",
    "Executor",
    "blas_threads",
    "chunk_slices",
    "command_blas_threads",
    "map_chunks",
    "resolve_workers",
    "retain_freed_memory",
    "shared_loads",
    "ship_once",
    "single_threaded_blas",
]

T = TypeVar("T")

_LIMITER: Any = None
_USERS = 0
_CONTROLLER: ThreadpoolController | None = None
_CONTROLLER_MODULES = -1  # len(sys.modules) when _CONTROLLER scanned the loaded libraries
_PIN_LOCK = threading.Lock()


def resolve_workers(n_workers: int | None) -> int:
    """Number of worker threads: ``None`` means one per available core.

    Parameters
    ----------
    n_workers : int or None
        A positive number, or None.

    Returns
    -------
    int

    Raises
    ------
    ValueError
        ``n_workers`` is not a positive integer or None.

    Examples
    --------
    >>> resolve_workers(3)
    3
    """
    if n_workers is None:
        try:
            return max(1, len(os.sched_getaffinity(0)))
        except AttributeError:  # pragma: no cover - platforms without sched_getaffinity
            return max(1, os.cpu_count() or 1)
    if isinstance(n_workers, bool) or not isinstance(n_workers, int) or n_workers < 1:
        msg = f"n_workers must be a positive integer or None; got {n_workers!r}"
        raise ValueError(msg)
    return n_workers


def chunk_slices(n: int, chunk_size: int) -> list[slice]:
    """Consecutive slices of at most ``chunk_size`` covering ``range(n)``.

    Parameters
    ----------
    n : int
        Number of items.
    chunk_size : int
        Largest slice length, >= 1.

    Returns
    -------
    list of slice

    Examples
    --------
    >>> chunk_slices(5, 2)
    [slice(0, 2, None), slice(2, 4, None), slice(4, 5, None)]
    """
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size < 1:
        msg = f"chunk_size must be a positive integer; got {chunk_size!r}"
        raise ValueError(msg)
    return [slice(i, min(i + chunk_size, n)) for i in range(0, n, chunk_size)]


@contextmanager
def single_threaded_blas() -> Iterator[None]:
    """Limit the BLAS libraries loaded in this process to one thread inside the block.

    The limit is process-wide, so the block counts its users: threads may enter and leave it in any order,
    and the original limits come back when the last one leaves.
    """
    global _LIMITER, _USERS, _CONTROLLER, _CONTROLLER_MODULES
    with _PIN_LOCK:
        if _USERS == 0:
            # a fresh scan whenever modules were imported since the last one, so that a BLAS loaded meanwhile
            # (scipy's own OpenBLAS, say) is limited too; otherwise the last scan (scanning costs milliseconds,
            # and the serial stages enter here once per model evaluation)
            if _CONTROLLER is None or len(sys.modules) != _CONTROLLER_MODULES:
                _CONTROLLER = ThreadpoolController()
                _CONTROLLER_MODULES = len(sys.modules)
            _LIMITER = _CONTROLLER.limit(limits=1, user_api="blas")
        _USERS += 1
    try:
        yield
    finally:
        with _PIN_LOCK:
            _USERS -= 1
            if _USERS == 0 and _LIMITER is not None:
                _LIMITER.restore_original_limits()
                _LIMITER = None


#: The environment variable that sets the BLAS threads of a ``cappe`` command: a positive number, or ``auto``
#: (the BLAS library's own choice, usually one per core); unset or empty: 1.
BLAS_THREADS_VARIABLE = "CAPPE_BLAS_THREADS"
#: What the BLAS libraries read when they load: a library that a command loads after its limit was set (scipy's
#: own OpenBLAS, imported on first use) starts with the command's thread count too.
_BLAS_LOAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")


def command_blas_threads(environ: Mapping[str, str] | None = None) -> int | None:
    """The BLAS threads a ``cappe`` command runs with, from ``CAPPE_BLAS_THREADS``: 1 by default, None for ``auto``.

    A command does many small linear-algebra calls (FRFs and fits of a few dozen DOF, per measurement, sample or
    frequency line); OpenBLAS's threads only add their synchronisation to each: ``cappe monitor ingest`` of 16
    measurements took 22 s on two OpenBLAS threads and 7 s on one (2-core machine).

    Parameters
    ----------
    environ : mapping of str to str, optional
        The environment to read (default ``os.environ``).

    Returns
    -------
    int or None
        The number of threads, or None where the user asked for the BLAS library's own choice.

    Raises
    ------
    ValueError
        The variable is neither a positive integer nor ``auto``.

    Examples
    --------
    >>> command_blas_threads({})
    1
    >>> command_blas_threads({"CAPPE_BLAS_THREADS": "4"}), command_blas_threads({"CAPPE_BLAS_THREADS": "auto"})
    (4, None)
    """
    text = (os.environ if environ is None else environ).get(BLAS_THREADS_VARIABLE, "").strip()
    if not text:
        return 1
    if text.lower() == "auto":
        return None
    if text.isascii() and text.isdigit() and int(text) >= 1:
        return int(text)
    msg = f"{BLAS_THREADS_VARIABLE} must be a positive number of threads or 'auto'; got {text!r}"
    raise ValueError(msg)


@contextmanager
def blas_threads(limit: int | None) -> Iterator[None]:
    """Run the block with BLAS on ``limit`` threads, also in BLAS libraries loaded inside it; None: as they are.

    The libraries loaded now are limited through threadpoolctl (as :func:`single_threaded_blas`, which this
    uses for one thread, so that the executors' own pinning nests inside); for those loaded later in the block
    the block sets ``OPENBLAS_NUM_THREADS``, ``MKL_NUM_THREADS`` and ``BLIS_NUM_THREADS``, which they read
    when they load. The variables and the limits come back when the block ends; a library loaded inside keeps
    the count it started with. Child processes started inside inherit the variables.

    Parameters
    ----------
    limit : int or None
        Threads per BLAS library (>= 1), or None to change nothing.

    Examples
    --------
    >>> from threadpoolctl import threadpool_info
    >>> with blas_threads(1):
    ...     all(lib["num_threads"] == 1 for lib in threadpool_info() if lib["user_api"] == "blas")
    True
    """
    if limit is None:
        yield
        return
    if isinstance(limit, bool) or not isinstance(limit, int) or limit < 1:
        msg = f"limit must be a positive integer or None; got {limit!r}"
        raise ValueError(msg)
    saved = {name: os.environ.get(name) for name in _BLAS_LOAD_VARIABLES}
    os.environ.update(dict.fromkeys(_BLAS_LOAD_VARIABLES, str(limit)))
    try:
        if limit == 1:
            with single_threaded_blas():
                yield
        else:
            with ThreadpoolController().limit(limits=limit, user_api="blas"):
                yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


_ALLOCATOR_TUNED = False
_ALLOCATOR_TRIED = False
#: glibc's own settings of the same knobs; where the user set one, cappe leaves the allocator alone.
_MALLOC_VARIABLES = ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_", "MALLOC_TOP_PAD_", "MALLOC_MMAP_MAX_")


def retain_freed_memory() -> bool:
    """Tune glibc's allocator once per process for the batched hot path; True if it was tuned (now or before).

    Each chunk of samples allocates and frees a few (chunk, n, n) arrays of 0.1-2 MB. glibc serves such blocks
    with fresh ``mmap`` pages and returns freed heap tops to the kernel, so every chunk faults its pages in again:
    on the 2-core test machine 16-20 % of the GSA's CPU time was system time. With arrays up to 32 MB taken from
    the heap and up to 512 MB of freed memory kept for reuse, that fell to 3 % and the GSA ran about 14 % faster
    (three interleaved pairs of runs, the machine tool's GSA at N = 512 on two threads). The price is memory the
    process keeps after a large run. Nothing is changed on other C libraries, or when the user set one of glibc's
    ``MALLOC_*_`` variables or a ``glibc.malloc`` tunable (``GLIBC_TUNABLES``). :meth:`Executor.map` calls it (in
    the calling process) and, once per worker process, a Dask map's first task (where the trim threshold of
    64 KiB that Dask's nanny sets by default does not count as the user's).
    """
    return _tune_allocator(os.environ)


#: What Dask's nanny puts in the environment of every worker process it starts unless told otherwise (its
#: configuration's ``distributed.nanny.pre-spawn-environ``): a trim threshold of 64 KiB. Set explicitly, it also
#: freezes glibc's mmap threshold at 128 KiB, so each chunk's arrays were fresh ``mmap`` pages again: on a
#: LocalCluster worker 20 modal-derivative evaluations of the three-axis machine took 4.6 CPU-s and 322 000 page
#: faults against 2.5 CPU-s and 75 000 in a plain process. Dask's default, not the user's choice: a worker
#: tunes its allocator as :func:`retain_freed_memory` does (2.8 CPU-s, 224 page faults).
_DASK_NANNY_MALLOC = {"MALLOC_TRIM_THRESHOLD_": "65536"}


def _tune_dask_worker_allocator() -> bool:
    """:func:`retain_freed_memory` in a Dask worker process, with the nanny's default trim threshold not counted
    as the user's setting (any other ``MALLOC_*_`` value or ``glibc.malloc`` tunable still leaves glibc alone)."""
    if _ALLOCATOR_TRIED:
        return _ALLOCATOR_TUNED
    environ = {k: v for k, v in os.environ.items() if _DASK_NANNY_MALLOC.get(k) != v}
    return _tune_allocator(environ)


def _tune_allocator(environ: Mapping[str, str]) -> bool:
    """Tune glibc's allocator once per process unless ``environ`` sets one of its variables."""
    global _ALLOCATOR_TUNED, _ALLOCATOR_TRIED
    if _ALLOCATOR_TRIED:
        return _ALLOCATOR_TUNED
    _ALLOCATOR_TRIED = True
    user_set = any(v in environ for v in _MALLOC_VARIABLES) or "glibc.malloc." in environ.get("GLIBC_TUNABLES", "")
    if sys.platform != "linux" or user_set:
        return False
    import ctypes
    import platform

    if platform.libc_ver()[0] != "glibc":
        return False
    try:
        libc = ctypes.CDLL("libc.so.6")
    except OSError:
        return False
    m_trim_threshold, m_top_pad, m_mmap_threshold = -1, -2, -3  # <malloc.h>
    # 32 MB is the largest mmap threshold every glibc accepts (HEAP_MAX_SIZE / 2 on 64-bit); each option is set
    # on its own, so one refusal leaves the others in place
    results = [libc.mallopt(option, value) == 1 for option, value in (
        (m_mmap_threshold, 32 << 20), (m_trim_threshold, 512 << 20), (m_top_pad, 16 << 20))]
    _ALLOCATOR_TUNED = all(results)
    return _ALLOCATOR_TUNED


#: The types whose objects a Dask map ships once per executor, with the attributes left behind (caches).
_SHIPPED_ONCE: dict[type, tuple[str, ...]] = {}


def ship_once(shipped: type, caches: Sequence[str] = ()) -> type:
    """Register the class ``shipped``: on a Dask executor its objects travel to each worker once, not with every map.

    For immutable objects that many maps read (a compiled model, a modal engine): the worker keeps its copy,
    unpickled once, until the executor closes. The attributes named in ``caches`` (dictionaries the object fills
    as it computes) are sent empty; the worker's copy fills its own.

    Parameters
    ----------
    shipped : type
        The class; its objects must not change after they are built (a cache aside).
    caches : sequence of str
        Instance attributes holding dictionaries that are caches.

    Returns
    -------
    type
        ``shipped`` (so that this can decorate a class).

    Examples
    --------
    >>> class Table:
    ...     def __init__(self):
    ...         self.values, self._cache = [1.0, 2.0], {}
    >>> ship_once(Table, caches=("_cache",)) is Table
    True
    """
    _SHIPPED_ONCE[shipped] = tuple(caches)
    return shipped


def _lean_copy(obj: Any) -> Any:
    """A shallow copy of a registered object with its caches emptied (what is sent)."""
    caches = next(names for cls, names in _SHIPPED_ONCE.items() if isinstance(obj, cls))
    if not caches or not hasattr(obj, "__dict__"):
        return obj
    clone = object.__new__(type(obj))
    state = dict(vars(obj))
    for name in caches:
        if isinstance(state.get(name), dict):
            state[name] = type(state[name])()
    clone.__dict__.update(state)
    return clone


class _SharingPickler:
    """cloudpickle with the registered objects (other than ``root``) written as references: ``share(obj)`` gives
    the reference and makes sure the object travels itself."""

    def __init__(self, share: Callable[[Any], str]) -> None:
        self.share = share

    def dumps(self, obj: Any, root: Any = None) -> bytes:
        import cloudpickle

        share = self.share
        registered = tuple(_SHIPPED_ONCE)

        class Pickler(cloudpickle.Pickler):  # type: ignore[misc]
            def persistent_id(self, value: Any) -> str | None:
                if registered and isinstance(value, registered) and value is not root:
                    return share(value)
                return None

        buffer = io.BytesIO()
        Pickler(buffer, protocol=pickle.HIGHEST_PROTOCOL).dump(obj)
        return buffer.getvalue()


# -- the worker's side of a Dask map: the objects shipped once, and the function of each recent map -------------
_WORKER_LOCK = threading.Lock()
_WORKER_SHARED: dict[str, Any] = {}
_WORKER_FUNCTIONS: OrderedDict[str, Callable[[Any], Any]] = OrderedDict()
_WORKER_FUNCTIONS_KEPT = 4
_SHARED_LOADS: Counter[str] = Counter()


class _SharedUnpickler(pickle.Unpickler):
    """Resolves the references of :class:`_SharingPickler` from this process's copies, unpickling a copy the first
    time from ``payloads`` (the scattered objects)."""

    def __init__(self, data: bytes, payloads: Mapping[str, bytes]) -> None:
        super().__init__(io.BytesIO(data))
        self.payloads = payloads

    def persistent_load(self, pid: Any) -> Any:
        token = str(pid)
        if token not in _WORKER_SHARED:
            _WORKER_SHARED[token] = _SharedUnpickler(self.payloads[token], self.payloads).load()
            _SHARED_LOADS[token] += 1
        return _WORKER_SHARED[token]


def _run_shared(item: Any, function: bytes, map_key: str, payloads: Mapping[str, bytes]) -> Any:
    """A Dask task: the map's function (unpickled once per process and map) applied to ``item``."""
    _tune_dask_worker_allocator()  # once per worker process (see _DASK_NANNY_MALLOC)
    with _WORKER_LOCK:
        func = _WORKER_FUNCTIONS.get(map_key)
        if func is None:
            func = _SharedUnpickler(function, payloads).load()
            _WORKER_FUNCTIONS[map_key] = func
            while len(_WORKER_FUNCTIONS) > _WORKER_FUNCTIONS_KEPT:
                _WORKER_FUNCTIONS.popitem(last=False)
    return func(item)


def _forget_shared(tokens: Sequence[str]) -> int:
    """Drop this process's copies of the shipped objects ``tokens`` and the functions of past maps."""
    with _WORKER_LOCK:
        _WORKER_FUNCTIONS.clear()
        return sum(_WORKER_SHARED.pop(token, None) is not None for token in tokens)


def shared_loads() -> dict[str, int]:
    """The objects shipped once (see :func:`ship_once`) that this process holds, by reference, and how often it
    unpickled each.

    A diagnostic for Dask workers (``client.run(shared_loads)``): every count is 1 when each object travelled once;
    a closed executor's objects are gone.

    Returns
    -------
    dict of str to int

    Examples
    --------
    >>> isinstance(shared_loads(), dict)
    True
    """
    with _WORKER_LOCK:
        return {token: _SHARED_LOADS[token] for token in _WORKER_SHARED}


class Executor:
    """Where :func:`map_chunks` runs its chunks (see the module): serial, threads, processes or Dask.

    Parameters
    ----------
    kind : str
        ``"serial"``, ``"threads"``, ``"processes"`` or a Dask scheduler address (``"tcp://127.0.0.1:8786"``).
    n_workers : int or None
        Threads or processes (``None``: one per core); ignored for Dask, whose cluster has its own workers.

    Notes
    -----
    An executor holds no resources between maps except a Dask client, which :meth:`close` (or leaving a
    ``with`` block) releases.

    Examples
    --------
    >>> with Executor("processes", n_workers=2) as ex:
    ...     ex.map(lambda s: list(range(s.start, s.stop)), [slice(0, 2), slice(2, 3)])
    [[0, 1], [2]]
    """

    LOCAL = ("serial", "threads", "processes")

    def __init__(self, kind: str = "threads", n_workers: int | None = None) -> None:
        if not isinstance(kind, str) or not (kind in self.LOCAL or "://" in kind):
            msg = (f"executor must be 'serial', 'threads', 'processes' or a Dask scheduler address like "
                   f"'tcp://HOST:PORT'; got {kind!r}")
            raise ValueError(msg)
        self.kind = kind
        self.n_workers = 1 if kind == "serial" else resolve_workers(n_workers)
        self._client: Any = None
        # the objects shipped once (ship_once): id -> (reference, the object, its scattered payload, the references
        # its payload holds); the object is kept so that its id is not reused while the workers hold its copy
        self._shipped: dict[int, tuple[str, Any, Any, tuple[str, ...]]] = {}

    @classmethod
    def coerce(cls, executor: Executor | str | None, n_workers: int | None = None) -> Executor:
        """An :class:`Executor` from an executor, a kind / address, or ``None`` (threads).

        Parameters
        ----------
        executor : Executor, str or None
            Returned as it is, or the ``kind`` of a new one (None: ``"threads"``).
        n_workers : int or None
            Workers of a new executor.

        Returns
        -------
        Executor
        """
        if isinstance(executor, Executor):
            return executor
        return cls("threads" if executor is None else executor, n_workers)

    def __repr__(self) -> str:
        return f"Executor({self.kind!r}, n_workers={self.n_workers})"

    def __getstate__(self) -> dict[str, Any]:
        # shipped along with the objects that hold it (a modal engine, say): the client stays here
        return {**self.__dict__, "_client": None, "_shipped": {}}

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Release the Dask client, if one was opened, and the workers' copies of the objects shipped once."""
        if self._client is not None:
            if self._shipped:
                tokens = [token for token, *_ in self._shipped.values()]
                try:
                    self._client.run(_forget_shared, tokens)
                except OSError:  # pragma: no cover - the cluster is gone; so are its copies
                    pass
                self._client.cancel([future for _, _, future, _ in self._shipped.values()])
            self._shipped.clear()
            self._client.close()
            self._client = None

    @property
    def client(self) -> Any:
        """The ``dask.distributed.Client`` of a scheduler address (opened on first use)."""
        if self.kind in self.LOCAL:
            msg = f"executor {self.kind!r} has no Dask client"
            raise ValueError(msg)
        if self._client is None:
            from distributed import Client

            self._client = Client(self.kind, set_as_default=False)  # type: ignore[no-untyped-call]
        return self._client

    def map(self, func: Callable[[Any], T], items: Sequence[Any],
            done: Callable[[Any], None] | None = None) -> list[T]:
        """``[func(item) for item in items]`` on this executor, in order; ``done(item)`` after each item.

        Parameters
        ----------
        func : callable
            ``func(item)`` -> result (picklable for processes and Dask).
        items : sequence
            The items.
        done : callable, optional
            ``done(item)`` called in this process after each item (e.g. a progress bar's update).

        Returns
        -------
        list
            The results in the order of ``items``.
        """
        items = list(items)

        def call_here(item: Any) -> T:
            value = func(item)
            if done is not None:
                done(item)
            return value

        workers = min(self.n_workers, max(len(items), 1))
        retain_freed_memory()
        if self.kind in ("serial", "threads"):
            with single_threaded_blas():
                if workers == 1:
                    return [call_here(item) for item in items]
                with ThreadPoolExecutor(max_workers=workers) as pool:
                    return list(pool.map(call_here, items))
        call = _Pinned(func)  # one BLAS thread in each worker process (and Dask worker thread)
        if self.kind == "processes":
            import multiprocessing

            import cloudpickle

            payload = cloudpickle.dumps(call)
            method = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"
            with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context(method),
                                     initializer=_install, initargs=(payload,)) as processes:
                local = {processes.submit(_run_installed, item): k for k, item in enumerate(items)}
                return _collect(as_completed(local), local, items, done)
        client = self.client
        used: set[str] = set()
        function = _SharingPickler(lambda obj: self._ship(obj, used)).dumps(call)
        key = f"cappe-map-{uuid.uuid4().hex}"
        remote = client.scatter(function, broadcast=True, hash=False)
        needed = {token: future for token, _, future, _ in self._shipped.values() if token in self._closure(used)}
        tasks = client.map(_run_shared, items, function=remote, map_key=key, payloads=needed, pure=False)
        try:
            return _collect(tasks, {f: k for k, f in enumerate(tasks)}, items, done)  # waits in item order
        finally:
            client.cancel([remote])

    def _ship(self, obj: Any, used: set[str]) -> str:
        """The reference of a registered object in a Dask map's function; scattered to the workers the first
        time (its own registered parts shipped as references too)."""
        entry = self._shipped.get(id(obj))
        if entry is None:
            inner: set[str] = set()
            lean = _lean_copy(obj)
            payload = _SharingPickler(lambda part: self._ship(part, inner)).dumps(lean, root=lean)
            token = f"cappe-shared-{uuid.uuid4().hex}"
            future = self.client.scatter(payload, broadcast=True, hash=False)
            entry = (token, obj, future, tuple(sorted(inner)))
            self._shipped[id(obj)] = entry
        used.add(entry[0])
        return entry[0]

    def _closure(self, tokens: set[str]) -> set[str]:
        """``tokens`` and the references their payloads hold, recursively."""
        inner = {token: deps for token, _, _, deps in self._shipped.values()}
        out: set[str] = set()
        todo = list(tokens)
        while todo:
            token = todo.pop()
            if token not in out:
                out.add(token)
                todo.extend(inner.get(token, ()))
        return out


class _Pinned:
    """A callable that runs ``func`` with BLAS on one thread (in whatever process it lands) and hands back its
    value with the warnings it raised (``(category, message)`` pairs), which the calling process raises again:
    a worker's warnings reach the user as a serial run's do. ``catch_warnings`` is process-wide state, so with
    several threads per Dask worker a warning may be attributed to another task of that worker (not lost)."""

    def __init__(self, func: Callable[[Any], Any]) -> None:
        self.func = func

    def __call__(self, item: Any) -> tuple[Any, list[tuple[type[Warning], str]]]:
        with single_threaded_blas(), warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            value = self.func(item)
        return value, [(w.category, str(w.message)) for w in caught]


_INSTALLED: Callable[[Any], Any] | None = None


def _install(payload: bytes) -> None:
    """Process-pool initializer: unpickle the mapped function once per worker process."""
    import pickle

    global _INSTALLED
    _INSTALLED = pickle.loads(payload)  # noqa: S301 - our own cloudpickle payload


def _run_installed(item: Any) -> Any:
    assert _INSTALLED is not None  # set by _install
    return _INSTALLED(item)


def _collect(finished: Any, index: dict[Any, int], items: list[Any], done: Callable[[Any], None] | None) -> list[Any]:
    """Results of ``finished`` futures (in completion order) put back in item order."""
    out: list[Any] = [None] * len(items)
    raised: list[list[tuple[type[Warning], str]]] = [[] for _ in items]
    for future in finished:
        k = index[future]
        out[k], raised[k] = future.result()
        if done is not None:
            done(items[k])
    for caught in raised:  # the workers' warnings, in item order (not the order the items finished in)
        for category, message in caught:
            warnings.warn(message, category, stacklevel=3)
    return out


def map_chunks(
    func: Callable[[slice], T],
    n: int,
    *,
    chunk_size: int,
    n_workers: int | None = None,
    executor: Executor | str | None = None,
    progress: bool = False,
    description: str = "",
) -> list[T]:
    """Apply ``func`` to consecutive chunks of ``range(n)``; results in chunk order.

    Parameters
    ----------
    func : callable
        Called with a ``slice`` of sample indices; must only read shared inputs.
    n : int
        Number of samples.
    chunk_size : int
        Samples per chunk; bounds the memory of one call.
    n_workers : int or None
        Threads (``None``: one per core) when no ``executor`` is given.
    executor : Executor, str or None
        Where the chunks run (see :class:`Executor`; default threads).
    progress : bool
        Show a progress bar (tqdm) over samples.
    description : str
        Label of the progress bar.

    Examples
    --------
    >>> map_chunks(lambda s: s.stop - s.start, 10, chunk_size=4, n_workers=2)
    [4, 4, 2]
    >>> map_chunks(lambda s: s.stop - s.start, 10, chunk_size=4, executor="serial")
    [4, 4, 2]
    """
    slices = chunk_slices(n, chunk_size)
    runner = Executor.coerce(executor, n_workers)
    bar: Any = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=n, desc=description or None, unit="sample")
    try:
        return runner.map(func, slices, done=None if bar is None else (lambda s: bar.update(s.stop - s.start)))
    finally:
        if bar is not None:
            bar.close()
        if runner is not executor:
            runner.close()
