"""Errors caused by the user's input, reported in one line by the CLI (exit code 2)."""


class UserError(Exception):
    """Bad input: a file, a name, a hyperparameter. The message says which and why."""


class DataError(UserError, ValueError):
    """Bad data. The message names the file (or source) and the problem."""


class ConfigError(UserError, TypeError):
    """A bad hyperparameter or option."""


def first_line(exc: BaseException, limit: int = 200) -> str:
    """The first line of ``exc``'s message, at most ``limit`` characters, for a report's one line."""
    text = str(exc).strip()
    return text.splitlines()[0][:limit] if text else "no message"
