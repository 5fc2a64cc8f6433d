"""The errors the command line reports in one line: those of the user's input
(exit code 2), and a job whose process did not return (exit code 1)."""


class UserError(Exception):
    """Bad input: a file, a name, a hyperparameter. The message says which and why."""


class DataError(UserError, ValueError):
    """Bad data. The message names the file (or source) and the problem."""


class ConfigError(UserError, TypeError):
    """A bad hyperparameter or option."""


class CallFailed(RuntimeError):
    """A job whose process did not return: killed at its limit, or it died."""


def first_line(exc: BaseException, limit: int = 200) -> str:
    """The first line of ``exc``'s message, at most ``limit`` characters, for a report's one line."""
    text = str(exc).strip()
    return text.splitlines()[0][:limit] if text else "no message"
