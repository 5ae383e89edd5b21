"""Scripts whose output is a published table (``docs/results/``, the README, docs/*.md):
``python benchmarks/results/<name>.py``."""
