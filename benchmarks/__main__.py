"""Run the benchmarks: ``python -m benchmarks`` (``make bench``; about 15 minutes on two cores)."""

from __future__ import annotations

from benchmarks import (
    bench_automated,
    bench_coverage,
    bench_estimate,
    bench_flexible,
    bench_identify,
    bench_intersample,
    bench_lm,
    bench_matrices,
    bench_modal,
    bench_monitor,
    bench_pipeline,
    bench_plan,
    bench_scaling,
    bench_sobol,
    bench_startup,
    bench_subproblem,
    bench_threads,
)


def main() -> None:
    bench_matrices.main()
    bench_modal.main()
    bench_flexible.main()
    bench_sobol.main()
    bench_identify.main()
    bench_estimate.main()
    bench_intersample.main()
    bench_coverage.main()
    bench_monitor.main()
    bench_pipeline.main()
    bench_automated.main()
    bench_plan.main()
    bench_subproblem.main()
    bench_lm.main()
    bench_scaling.main()
    bench_startup.main()
    bench_threads.main()


if __name__ == "__main__":
    main()
