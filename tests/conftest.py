"""Shared fixtures, one BLAS thread in each pytest-xdist worker, and the units of work of ``make test``."""

from __future__ import annotations

import os
from collections import OrderedDict
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

from cappe.model import load_model

# Hypothesis times its examples and its data generation by the wall clock: on a loaded CI machine (two workers,
# other jobs beside them) a fast example can take seconds. Neither is a property of cappe, so neither fails a
# test; the tests bound what they must bound themselves (CPU time: tests/cli/test_fuzz_inputs.py).
settings.register_profile("cappe", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("cappe")


def pytest_configure(config: pytest.Config) -> None:
    """In a pytest-xdist worker (``make test`` runs one per core), BLAS and OpenMP on one thread.

    The workers already fill the cores; BLAS threads on top of them only oversubscribe (and slow down the many
    small linear-algebra calls of the tests, as in the commands: see cappe.parallel). The variables reach the
    libraries loaded later and the subprocesses a test starts; threadpoolctl limits the ones loaded now.
    """
    if not os.environ.get("PYTEST_XDIST_WORKER"):
        return
    from threadpoolctl import ThreadpoolController

    for name in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS", "OMP_NUM_THREADS"):
        os.environ[name] = "1"
    ThreadpoolController().limit(limits=1)  # for the life of the worker


#: Test files whose tests ``make test`` sends one by one to whichever worker is free, mapped to the test functions
#: whose cases stay together, in order, on one worker. Every other file runs whole on one worker, as with
#: ``--dist loadfile`` (its module fixtures built once). A file of many independent slow cases held one worker for
#: minutes after the others were done; spread, each worker builds the module fixtures it needs once.
SPREAD: dict[str, tuple[str, ...]] = {
    "tests/cli/test_option_audit.py": (),  # 350 command-line cases; its data folder (~15 s) is built once per run
    # the README's commands read each other's files: one unit, in order
    "tests/cli/test_model_cli.py": ("test_readme_command_runs",),
}


#: Units of work (see :func:`work_unit`) that ``make test`` and ``make test-slow`` start first, longest first (wall
#: seconds on one worker in the last full runs, quiet host). xdist's own order starts the units of most tests first;
#: a long unit of few tests then started near the end and held one worker while the other had nothing left to do
#: (``make test-slow``: the flexible bed's 57 s identification started at 120 s of 200). A unit not in the run
#: being scheduled is passed over.
FIRST: tuple[str, ...] = (
    "tests/cli/test_model_cli.py::test_readme_command_runs",  # 180 s, in order
    "tests/monitor/test_calibration.py",  # extended: 84 s (1000 healthy measurements of the independent generator)
    "tests/monitor/test_chain.py",  # 65 s (extended: 25 s)
    "tests/library/test_uniaxial_machine_tool_flexible_bed.py",  # extended: 57 s
    "tests/cli/test_model_cli.py::test_demo_monitoring_finds_each_fault",  # extended: 46 s
    "tests/cli/test_monitor_cli.py",  # 39 s
    "tests/estimate/test_machine_tool_identification.py",  # extended: 38 s
    "tests/model/test_reference_derivations.py",  # 36 s
    "tests/estimate/test_two_step_weighting.py",  # 33 s
    "tests/test_parallel.py",  # 31 s
)


def work_unit(nodeid: str) -> str:
    """The unit of work of a test for ``make test``'s scheduler: its file, or itself in a :data:`SPREAD` file."""
    path, _, rest = nodeid.partition("::")
    if path not in SPREAD:
        return path
    name = rest.split("[", 1)[0]
    return f"{path}::{name}" if name in SPREAD[path] else nodeid


def first_to_front(workqueue: OrderedDict[str, object]) -> None:
    """Move the first unit of :data:`FIRST` still waiting in ``workqueue`` (xdist's queue of units) to its front."""
    for unit in FIRST:
        if unit in workqueue:
            workqueue.move_to_end(unit, last=False)
            return


@pytest.hookimpl(optionalhook=True)  # a hook of pytest-xdist, absent without it
def pytest_xdist_make_scheduler(config: pytest.Config, log: object) -> object:
    """``--dist loadgroup`` (``make test``) schedules by :func:`work_unit`, the units of :data:`FIRST` first.

    pytest-xdist's own loadgroup reads ``xdist_group`` marks by rewriting ``item._nodeid``, which pytest 9 no longer
    reads (the groups were silently ignored), so the groups are made here, from the node ids, by a scheduler of
    xdist's public hook.
    """
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class FileOrTestScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return work_unit(nodeid)

        def _assign_work_unit(self, node: object) -> None:
            first_to_front(self.workqueue)
            super()._assign_work_unit(node)  # type: ignore[arg-type]

    return FileOrTestScheduling(config, log)  # type: ignore[arg-type]


@pytest.fixture(scope="session")
def two_mass():
    return load_model("builtin:two-mass-rig")


@pytest.fixture(scope="session")
def spindle():
    return load_model("builtin:spindle-bearing")


def build_slide():
    """A base on mounts with a slide moving along axis z on two guide shoes (CASE 3), both damping kinds.

    The guide stiffness follows a preload law ``kg0 * (Fp / 1000)**(1/3)`` so that one coefficient is
    non-linear in a parameter; sensors sit on the base and on the slide.
    """
    from cappe.model import StructureBuilder

    b = StructureBuilder("slide")
    b.parameter("mb", 40.0, unit="kg", kind="mass")
    b.parameter("ms", 12.0, unit="kg", kind="mass")
    b.parameter("Jb", 0.9, unit="kg m^2", kind="inertia")
    b.parameter("Js", 0.2, unit="kg m^2", kind="inertia")
    b.parameter("km", 8.0e6, unit="N/m", kind="stiffness")
    b.parameter("kmr", 4.0e5, unit="N m/rad", kind="stiffness")
    b.parameter("kg0", 3.0e7, unit="N/m", kind="stiffness")
    b.parameter("Fp", 1500.0, unit="N", kind="other")
    b.parameter("cm", 900.0, unit="N s/m", kind="damping")
    b.parameter("cg", 300.0, unit="N s/m", kind="damping")
    b.parameter("eta", 0.03, unit="1", kind="loss")
    b.axis("z", [0.1, 0.25, 0.4])
    b.body("base", mass="mb", inertia={"xx": "Jb", "yy": "1.2*Jb", "zz": "0.7*Jb"})
    b.body("slide", mass="ms", inertia={"xx": "Js", "yy": "1.1*Js", "zz": "0.8*Js"}, position=[0, 0.05, "z"])
    mount = {d: "km" if d in ("x", "y", "z") else "kmr" for d in ("x", "y", "z", "rx", "ry", "rz")}
    for i, (x, y) in enumerate(((-0.3, -0.2), (0.3, -0.2), (0.0, 0.25))):
        b.element(f"mount{i}", bodies=("ground", "base"), at=[x, y, -0.1], stiffness=mount,
                  damping={"x": "cm", "y": "cm", "z": "cm"}, loss={"rx": "eta"})
    guide = {"x": "kg0*(Fp/1000)**(1/3)", "y": "0.8*kg0*(Fp/1000)**(1/3)"}
    for i, dz in enumerate((-0.06, 0.06)):
        b.element(f"shoe{i}", bodies=("base", "slide"), at=[0.02, 0.05, f"z + {dz}"], stiffness=guide,
                  damping={"x": "cg"}, loss={"y": "eta"})
    b.element("drive", bodies=("base", "slide"), at=[0, 0.05, "z"], stiffness={"z": "kg0/10", "rz": "kmr"}, damping={"z": "cg"})
    b.sensor("tool", body="slide", point=[0, 0.1, 0.0])
    b.sensor("top", body="base", point=[0.2, 0.2, 0.1])
    b.input("F", body="slide", direction="x")
    b.output("d", body="slide", direction="x")
    return b.build()


@pytest.fixture(scope="session")
def slide():
    return build_slide()


def _realdata_folder() -> Path | None:
    """The public measured data (``shared/realdata`` beside the checkout or above it; ``CAPPE_REALDATA`` wins)."""
    if os.environ.get("CAPPE_REALDATA"):
        return Path(os.environ["CAPPE_REALDATA"])
    for parent in Path(__file__).resolve().parents:
        candidate = parent / "shared" / "realdata"
        if candidate.is_dir():
            return candidate
    return None


@pytest.fixture(scope="session")
def realdata() -> Path:
    """Folder of the real measured data (see its SOURCES.md); skipped where absent, failed where CI promises it
    (CAPPE_REQUIRE_SERVICES=1). The files are read in place, never copied into the repository."""
    folder = _realdata_folder()
    if folder is None or not (folder / "SOURCES.md").is_file():
        reason = "the real measured data (shared/realdata, or CAPPE_REALDATA) are not on this machine"
        if os.environ.get("CAPPE_REQUIRE_SERVICES") == "1":
            pytest.fail(f"{reason}, and CAPPE_REQUIRE_SERVICES=1 requires them")
        pytest.skip(reason)
    return folder
