"""The one exception type a user should ever see: the CLI prints it as a single line."""


class QuadfdiError(Exception):
    """A problem with the user's input (file, field, value); printed as one line, exit code 2."""
