"""The one exception type for bad user input."""


class InputError(ValueError):
    """Input that a user can fix: a bad file, field, option or value.

    The message is one line that names the file, field or option and says
    what was expected. The CLI prints it and exits with status 2.
    """


class ExternalError(RuntimeError):
    """Something outside the toolkit failed: network, a remote server.

    The CLI prints the one-line message and exits with status 1.
    """
