"""Speed and endurance benchmarks: every speed is a ratio against a baseline measured in
the same run (``python benchmarks/performance/<name>.py``)."""
