"""The bottom floor of the harness: user errors, cost limits, option values, small text and JSON helpers."""
