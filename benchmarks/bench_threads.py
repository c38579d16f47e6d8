"""Commands at their single-thread BLAS speed by default: each command's default run against the pinned one.

Every ``cappe`` command runs its work with BLAS on one thread unless ``CAPPE_BLAS_THREADS`` says otherwise
(:func:`cappe.parallel.command_blas_threads`): its work is many small linear-algebra calls, which OpenBLAS's threads
only slow down. This benchmark runs a few such commands in this one process through ``cappe.cli.main``, three ways,
interleaved, and keeps the shortest of the repeats of each:

- ``default``: as a user runs them (``CAPPE_BLAS_THREADS`` unset);
- ``pinned``: BLAS explicitly on one thread (threadpoolctl around the call and ``CAPPE_BLAS_THREADS=1``);
- ``blas's own``: ``CAPPE_BLAS_THREADS=auto``, the BLAS library's own thread count (one per core: what every
  command ran with before the default existed).

``default / pinned`` must stay near 1 (it is printed as a regression above 1.5); ``blas's own / pinned`` shows
what the default saves on this machine. ``python -m benchmarks.bench_threads`` writes
``benchmarks/results/threads.json``.
"""

from __future__ import annotations

import contextlib
import io
import os
import shutil
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

from threadpoolctl import threadpool_info, threadpool_limits

from benchmarks._common import write_results
from cappe.cli import main as cappe

REPEAT = 3
#: default / pinned above this is a regression: the default no longer runs at single-thread speed
TOLERANCE = 1.5


@contextlib.contextmanager
def _mode(mode: str) -> Iterator[None]:
    saved = os.environ.get("CAPPE_BLAS_THREADS")
    os.environ.pop("CAPPE_BLAS_THREADS", None)
    if mode == "pinned":
        os.environ["CAPPE_BLAS_THREADS"] = "1"
    elif mode == "blas's own":
        os.environ["CAPPE_BLAS_THREADS"] = "auto"
    try:
        with threadpool_limits(limits=1, user_api="blas") if mode == "pinned" else contextlib.nullcontext():
            yield
    finally:
        os.environ.pop("CAPPE_BLAS_THREADS", None)
        if saved is not None:
            os.environ["CAPPE_BLAS_THREADS"] = saved


def _run(argv: list[str]) -> None:
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()) as err:
        code = cappe(argv)
    if code != 0:
        msg = f"cappe {' '.join(argv)} failed ({code}): {err.getvalue()}"
        raise RuntimeError(msg)


def _cases(folder: Path) -> list[tuple[str, Callable[[], list[str]]]]:
    """(label, a function returning the argv of one run) for each command; set-up files are made here."""
    store = folder / "spindle.db"
    _run(["monitor", "init", str(store), "--machine", "spindle-01", "--model", "builtin:spindle-bearing", "--outputs",
          "sx,sy,hax,hay,haz,htax", "--band", "150:1000"])
    _run(["monitor", "simulate", "healthy", "--store", str(store), "-n", "8", "--seed", "1", "-o", str(folder / "day")])
    _run(["model", "modes", "builtin:spindle-bearing", "--modal-out", str(folder / "ref.json"), "--sensors",
          "nose,housing_top"])

    def ingest() -> list[str]:
        fresh = folder / "ingest.db"
        shutil.copyfile(store, fresh)  # every run ingests the same 8 measurements into the initialised store
        return ["monitor", "ingest", str(fresh), "--manifest", str(folder / "day/scenario.json")]

    return [
        ("monitor ingest (8 measurements)", ingest),
        ("sensitivity --sobol (spindle, N=64)", lambda: [
            "sensitivity", "builtin:spindle-bearing", "--sobol", "--reference", str(folder / "ref.json"), "--n", "64",
            "--criteria", "macxp,ndd2"]),
        ("study direct (2 seeds x 2 noises)", lambda: [
            "study", "builtin:two-mass-rig", "--method", "direct", "--setting", "instruments=model", "--set", "c11=20",
            "--set", "c22=4", "--noise", "0,0.01", "--seeds", "2", "--duration", "1"]),
    ]


def main() -> None:
    modes = ["default", "pinned", "blas's own"]
    threads = sorted({lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"})
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for label, argv in _cases(Path(tmp)):
            _run(argv())  # warm-up: imports, compiled models, caches
            times: dict[str, list[float]] = {m: [] for m in modes}
            for _ in range(REPEAT):
                for mode in modes:
                    args = argv()
                    with _mode(mode):
                        t0 = time.perf_counter()
                        _run(args)
                        times[mode].append(time.perf_counter() - t0)
            best = {m: min(t) for m, t in times.items()}
            ratio, saved = best["default"] / best["pinned"], best["blas's own"] / best["pinned"]
            flag = "  REGRESSION: the default is not at single-thread speed" if ratio > TOLERANCE else ""
            print(f"{label:38s} default {best['default']:6.2f} s, pinned {best['pinned']:6.2f} s, BLAS's own "
                  f"{best[modes[2]]:6.2f} s: default/pinned {ratio:4.2f}, own/pinned {saved:4.2f}{flag}")
            rows.append({"command": label, "default_s": best["default"], "pinned_s": best["pinned"],
                         "blas_own_s": best["blas's own"], "default_over_pinned": ratio,
                         "blas_own_over_pinned": saved, "blas_own_threads": threads})
    print(f"BLAS's own thread count here: {threads}; wrote {write_results('threads', rows)}")


if __name__ == "__main__":
    main()
