"""Benchmarks that write JSON (and figures): one module per benchmark, each with ``run``."""

__all__: list[str] = []
