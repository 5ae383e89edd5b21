"""Benchmarks and tools that are not part of the installed package, by purpose:

* ``benchmarks/performance/``: speed and endurance (physics and env-step throughput, training
  speed, the work meter's cost, the random-action soak), as ratios against a baseline measured
  in the same run;
* ``benchmarks/results/``: the scripts whose output is a published table (the learning table,
  the condition tables, the scripted expert's baseline, the zoo's choice, ...);
* ``benchmarks/probes/``: research probes and QA (reward audits, critic and expert-agreement
  probes, the stop audit, the scene tour);
* ``benchmarks/common/``: the one output layer they share: a results document (JSON) rendered
  to a Markdown page (``docs/results/``) with :mod:`rehabbot.common.text_tables`.

Each script runs on its own from the repository root:
``python benchmarks/<kind>/<name>.py``."""
