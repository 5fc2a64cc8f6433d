"""Errors caused by the user's input, reported in one line by the CLI (exit code 2)."""


class UserError(Exception):
    """Bad input: a file, a name, a hyperparameter. The message says which and why."""


class DataError(UserError, ValueError):
    """Bad data. The message names the file (or source) and the problem."""


class ConfigError(UserError, TypeError):
    """A bad hyperparameter or option."""
