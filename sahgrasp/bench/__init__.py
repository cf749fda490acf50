"""Benchmarks that write JSON (and figures): one module per benchmark, each with ``run``.

:mod:`sahgrasp.bench.report` holds what they share: progress on stderr (off with ``quiet``) and
``summary_table(document)``, a one-screen table of any benchmark's JSON document.
"""

__all__: list[str] = []
