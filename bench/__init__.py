"""The benchmarks behind BENCHMARKS.md (`python -m bench.run_all`) and their helpers, run from the repository root as
`python -m bench.NAME`. Not part of the installed package (the wheel ships `sea_hil` only); one-off studies are in
`bench.studies`."""
