"""The repository's benchmarks and the fault campaign; run each as ``python3 benchmarks/<name>.py``. A package so
that tests can import the fault campaign's log kit as ``benchmarks.fuzz_certify``; not installed."""
