"""The one exception type for errors a user can cause (bad scene files, options, EXR files)."""


class HarnessError(Exception):
    """A user-caused error. ``str(err)`` is one line: the file, the key or option, and what was expected.

    Only the CLI turns it into a printed line and exit code 2.
    """

    def __init__(self, where: str, message: str):
        super().__init__(f"{where}: {message}" if where else message)
        self.where = where
        self.message = message
