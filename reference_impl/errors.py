"""The one error type the core raises for input a caller can get wrong."""


class SettingsError(ValueError):
    """A setting or an input array is not what the core accepts.

    ``key`` names the offending setting or array; the message says what was expected.
    """

    def __init__(self, key: str, message: str):
        super().__init__(f"{key}: {message}")
        self.key = key
        self.message = message
