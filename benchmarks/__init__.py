"""Benchmarks and tools that are not part of the installed package (soak, throughput,
scene tour, results tables); each script runs on its own: ``python benchmarks/<name>.py``."""
