"""Start-up time of the ``cappe`` command, against the interpreter's own start and numpy's import.

Each command runs in a fresh interpreter (as a user or a monitoring script calls it), the median of seven runs;
the baselines are measured in the same run: ``python -c pass`` (the least any command can take) and
``python -c "import numpy"`` (what every command needs). ``cappe --help`` and the parsing of every command import
none of sympy, scipy or the estimators; a command loads what it uses when it runs.
"""

from __future__ import annotations

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
]


def wall(command: list[str], repeat: int = 7) -> float:
    """Median wall time (s) of ``command`` (a fresh interpreter each time)."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run(command, check=True, capture_output=True)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    rows = []
    walls = [wall(command) for _, command in CASES]
    base = walls[0]  # python -c pass
    for (label, _), seconds in zip(CASES, walls, strict=True):
        rows.append({"command": label, "wall_s": seconds, "above_interpreter_s": seconds - base})
        print(f"{label:42s} {seconds:6.2f} s  (interpreter start + {seconds - base:5.2f} s)")
    write_results("startup", rows)


if __name__ == "__main__":
    main()
