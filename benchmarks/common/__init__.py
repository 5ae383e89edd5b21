"""The output layer every benchmark shares: results documents (JSON) and their Markdown
pages (:mod:`benchmarks.common.documents`), the machine a timing ran on
(:mod:`benchmarks.common.machine`)."""
