"""Packaging measurements: the wheel, a core install and the tracked tree, by script
(``python benchmarks/packaging/<name>.py``)."""
