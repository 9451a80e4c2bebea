"""Benchmarks of pscc (``make bench``): they write ``BENCHMARKS.md``; no timing is asserted in tests."""
