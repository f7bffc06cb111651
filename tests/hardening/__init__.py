"""Hostile-input suites of issue 13 that span the readers of several packages."""
