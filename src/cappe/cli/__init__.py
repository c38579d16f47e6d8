"""Command-line interface ``cappe``: parses, calls the public API, prints and writes files."""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence

from cappe._version import __version__
from cappe.cli import (
    demo,
    estimate,
    extract_modes,
    fit,
    frf,
    identify,
    model,
    monitor,
    plan_test,
    sensitivity,
    simulate,
    study,
)
from cappe.cli._common import EXIT_USAGE, run_guarded

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="cappe",
        description="Computer-aided physical parameter estimation for machine structures.",
    )
    parser.add_argument("--version", action="version", version=f"cappe {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    model.register(sub)
    sensitivity.register(sub)
    simulate.register(sub)
    frf.register(sub)
    fit.register(sub)
    extract_modes.register(sub)
    estimate.register(sub)
    study.register(sub)
    identify.register(sub)
    plan_test.register(sub)
    monitor.register(sub)
    demo.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; returns the exit code (0 success, 1 failure, 2 usage error).

    Parameters
    ----------
    argv : sequence of str, optional
        The arguments after ``cappe`` (e.g. ``["model", "modes", "builtin:two-mass-rig"]``); default
        ``sys.argv[1:]``.

    Returns
    -------
    int
        The exit code.
    """
    parser = build_parser()
    try:
        args = parser.parse_args(list(argv) if argv is not None else None)
    except SystemExit as exc:
        return int(exc.code) if isinstance(exc.code, int) else EXIT_USAGE
    level = logging.WARNING - 10 * min(args.verbose, 2)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    return run_guarded(args.func, args)


if __name__ == "__main__":
    sys.exit(main())
