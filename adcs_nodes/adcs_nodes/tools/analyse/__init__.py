"""Analysing runs: reports, exports, metrics, the papers' tables, studies."""
