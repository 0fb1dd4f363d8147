"""One-off studies and diagnostics: scripts behind the dated logs of docs/studies/, the profilers of the benchmarks'
diagnostic options (`bench_cpu_per_sample --profile`, `bench_scale --session`, `bench_soak --tracemalloc`), A/B
timings of hot parts. Run by hand as `python -m bench.studies.NAME`; no benchmark figure and nothing in CI runs
them (tests/test_bench_studies.py imports each)."""
