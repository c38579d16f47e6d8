"""Start-up time of the ``cappe`` command, against the interpreter's own start and numpy's import.

Each command runs in a fresh interpreter (as a user or a monitoring script calls it), the median of seven runs;
the baselines are measured in the same run: ``python -c pass`` (the least any command can take) and
``python -c "import numpy"`` (what every command needs). ``cappe --help`` and the parsing of every command import
none of sympy, scipy or the estimators; a command loads what it uses when it runs. Beside the wall time, the
CPU seconds of each run (user + system, from the children's resource usage): the number that holds on a loaded
machine (the test suite starts ~40 such processes). The last cases are the imports a monitoring command cannot
avoid (scipy.stats for detection, pandas and sqlalchemy for the store, sympy for the model) and the whole
``cappe.monitor`` package.
"""

from __future__ import annotations

import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

from benchmarks._common import write_results

#: the console script that ``pip install`` made beside this interpreter (what users run)
CAPPE = str(Path(sys.executable).with_name("cappe"))
#: (label, command line): the baselines, then commands that need more and more of the library
CASES: list[tuple[str, list[str]]] = [
    ("python -c pass", [sys.executable, "-c", "pass"]),
    ('python -c "import numpy"', [sys.executable, "-c", "import numpy"]),
    ("cappe --help", [CAPPE, "--help"]),
    ("cappe estimate --help", [CAPPE, "estimate", "--help"]),
    ("cappe model show builtin:two-mass-rig", [CAPPE, "model", "show", "builtin:two-mass-rig"]),
    ("cappe model modes builtin:two-mass-rig", [CAPPE, "model", "modes", "builtin:two-mass-rig"]),
    ("cappe monitor status --help", [CAPPE, "monitor", "status", "--help"]),
    ("python -c 'import <monitoring libraries>'",
     [sys.executable, "-c", "import numpy, sympy, scipy.linalg, scipy.optimize, scipy.stats, scipy.signal, pandas, "
                            "sqlalchemy"]),
    ('python -c "import cappe.monitor"', [sys.executable, "-c", "import cappe.monitor"]),
]


def wall(command: list[str], repeat: int = 7) -> float:
    """Median wall time (s) of ``command`` (a fresh interpreter each time)."""
    return measure(command, repeat)[0]


def measure(command: list[str], repeat: int = 7) -> tuple[float, float]:
    """Median wall time and median CPU time (user + system, s) of ``command``, a fresh interpreter each time."""
    walls, cpus = [], []
    for _ in range(repeat):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run(command, check=True, capture_output=True)
        walls.append(time.perf_counter() - t0)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpus.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return statistics.median(walls), statistics.median(cpus)


def main() -> None:
    rows = []
    measured = [measure(command) for _, command in CASES]
    base = measured[0][0]  # python -c pass
    for (label, _), (seconds, cpu) in zip(CASES, measured, strict=True):
        rows.append({"command": label, "wall_s": seconds, "above_interpreter_s": seconds - base, "cpu_s": cpu})
        print(f"{label:42s} {seconds:6.2f} s  (interpreter start + {seconds - base:5.2f} s)  CPU {cpu:5.2f} s")
    write_results("startup", rows)


if __name__ == "__main__":
    main()
