"""Run the benchmarks: ``python -m benchmarks`` (``make bench``)."""

from __future__ import annotations

from benchmarks import bench_estimate, bench_identify, bench_matrices, bench_modal, bench_sobol


def main() -> None:
    bench_matrices.main()
    bench_modal.main()
    bench_sobol.main()
    bench_identify.main()
    bench_estimate.main()


if __name__ == "__main__":
    main()
