"""Executors for the hot path: chunks of samples on local threads, BLAS pinned to one thread.

numpy's batched LAPACK calls (``eigh``, ``cholesky``, ``inv``, stacked ``matmul``) release the GIL, so
threads over chunks of samples scale with the cores, while OpenBLAS's own threading gains little on small
matrices and can collapse when numpy and scipy calls interleave. Inside :func:`map_chunks` BLAS therefore
runs single-threaded and the parallelism is over samples. Every chunk computes each sample the same way,
so results do not depend on the chunk size or the number of workers.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from typing import Any, TypeVar

from threadpoolctl import ThreadpoolController

__all__ = ["chunk_slices", "map_chunks", "resolve_workers", "single_threaded_blas"]

T = TypeVar("T")

_CONTROLLER: ThreadpoolController | None = None


def resolve_workers(n_workers: int | None) -> int:
    """Number of worker threads: ``None`` means one per available core.

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
    """Limit the BLAS libraries loaded in this process to one thread inside the block."""
    global _CONTROLLER
    if _CONTROLLER is None:
        _CONTROLLER = ThreadpoolController()
    with _CONTROLLER.limit(limits=1, user_api="blas"):
        yield


def map_chunks(
    func: Callable[[slice], T],
    n: int,
    *,
    chunk_size: int,
    n_workers: int | None = None,
    progress: bool = False,
    description: str = "",
) -> list[T]:
    """Apply ``func`` to consecutive chunks of ``range(n)`` on threads; results in chunk order.

    Parameters
    ----------
    func : callable
        Called with a ``slice`` of sample indices; must only read shared inputs.
    n : int
        Number of samples.
    chunk_size : int
        Samples per chunk; bounds the memory of one call.
    n_workers : int or None
        Threads (``None``: one per core).
    progress : bool
        Show a progress bar (tqdm) over samples.
    description : str
        Label of the progress bar.

    Examples
    --------
    >>> map_chunks(lambda s: s.stop - s.start, 10, chunk_size=4, n_workers=2)
    [4, 4, 2]
    """
    slices = chunk_slices(n, chunk_size)
    workers = min(resolve_workers(n_workers), max(len(slices), 1))
    bar: Any = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=n, desc=description or None, unit="sample")

    def run(s: slice) -> T:
        out = func(s)
        if bar is not None:
            bar.update(s.stop - s.start)
        return out

    try:
        with single_threaded_blas():
            if workers == 1:
                return [run(s) for s in slices]
            with ThreadPoolExecutor(max_workers=workers) as pool:
                return list(pool.map(run, slices))
    finally:
        if bar is not None:
            bar.close()
