"""Research probes and QA tools (diagnoses of failed runs, reward and stop audits, the scene
tour): ``python benchmarks/probes/<name>.py``."""
