"""The exception types for bad user input and for failures outside the toolkit.

An error names what the user gave by the library's own name for it, the
parameter (``block_s 0.001: ...``), and lists the parameters it names in
``param``; the command line rewrites each to the option the user typed
(``--block-s 0.001: ...``). A library message therefore never starts with
an option such as ``--block-s``: a user of the Python API never typed one.
"""


class _NamesParameters:
    """Mixin: the parameters a message names, kept on the exception as ``params``."""

    def __init__(self, message, *, param=()):
        super().__init__(message)
        #: tuple of str: library parameter names the message mentions as whole words.
        self.params = (param,) if isinstance(param, str) else tuple(param)


class InputError(_NamesParameters, ValueError):
    """Input that a user can fix: a bad file, field, parameter or value.

    The message is one line that names the file, field or parameter and says
    what was expected. The CLI prints it, parameters as options, and exits
    with status 2.

    Parameters
    ----------
    message : str
    param : str or tuple of str, optional
        The library parameter(s) the message names, e.g. ``"block_s"``.
    """


class ExternalError(_NamesParameters, RuntimeError):
    """Something outside the toolkit failed: network, a remote server.

    The CLI prints the one-line message (parameters as options, as for
    :class:`InputError`) and exits with status 1.
    """
