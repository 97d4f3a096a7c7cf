"""The one exception type for errors a user can cause (bad scene files, options, EXR files)."""


class HarnessError(Exception):
    """A user-caused error. ``str(err)`` is one line: the file, the key or option, and what was expected.

    Only the CLI turns it into a printed line and exit code 2.
    """

    def __init__(self, where: str, message: str):
        super().__init__(f"{where}: {message}" if where else message)
        self.where = where
        self.message = message


def read_user_text(path, *, missing: str, where: str | None = None) -> str:
    """The UTF-8 text of a file the user named. A one-line HarnessError at ``where`` (default: the path) otherwise:
    ``missing`` when there is no such file, ``cannot read: ...`` for anything else that stops the read."""
    from pathlib import Path

    where = str(path) if where is None else where
    try:
        return Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise HarnessError(where, missing) from None
    except (OSError, UnicodeDecodeError) as err:
        raise HarnessError(where, f"cannot read: {err}") from None


def read_user_toml(path, *, missing: str) -> dict:
    """:func:`read_user_text`, parsed as TOML; a syntax error, an integer beyond Python's digit limit or absurd
    nesting is one line too (``invalid TOML: ...``). (Scene files have their own reader, with line and column.)"""
    import tomllib

    text = read_user_text(path, missing=missing)
    try:
        return tomllib.loads(text)
    except (ValueError, RecursionError) as err:  # tomllib.TOMLDecodeError is a ValueError
        raise HarnessError(str(path), f"invalid TOML: {err}") from None
