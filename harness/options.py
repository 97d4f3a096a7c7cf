"""Checks of command-line option values shared by the subcommands: one line naming the option (exit code 2)."""

from __future__ import annotations

from harness.errors import HarnessError


def require_positive(option: str, value: int) -> int:
    """``value`` if it is >= 1, else the user error "OPTION: expected a positive integer, got VALUE"."""
    if value < 1:
        raise HarnessError(option, f"expected a positive integer, got {value}")
    return value


def require_non_negative(option: str, value: int) -> int:
    """``value`` if it is >= 0 (seeds), else the user error "OPTION: expected a non-negative integer, got VALUE"."""
    if value < 0:
        raise HarnessError(option, f"expected a non-negative integer, got {value}")
    return value
