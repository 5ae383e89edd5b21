"""What the benchmark scripts share: the command-line bootstrap (:mod:`benchmarks.common.cli`),
results documents (JSON) and their Markdown pages (:mod:`benchmarks.common.documents`), the
machine a timing ran on (:mod:`benchmarks.common.machine`), and the measurements that the
scripts publish and the tests assert: IQM intervals across seeds
(:mod:`benchmarks.common.aggregate`), the batched env against the CPU env
(:mod:`benchmarks.common.batch_parity`), a patient's condition measured as a clinic would
(:mod:`benchmarks.common.condition_probes`) and the audits of a reward design
(:mod:`benchmarks.common.reward_audit`). None of it is part of the installed package."""
