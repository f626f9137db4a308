"""The one exception type for user errors (one line, exit status 2), shared by every command.

Its own module so that ``python -m cell.cli`` (where ``cell.cli`` runs as ``__main__``) and the
commands that raise it agree on the class.
"""


class UserError(Exception):
    """An error in what the user gave us: reported in one line, exit status 2."""
