"""Validation and benchmark harness for Monte Carlo renderers (adapters, judges, CLI)."""
