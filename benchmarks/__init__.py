"""Performance harness: ratios measured in one run, written to benchmarks/results/*.json."""
