"""Errors that mean "the user's input is wrong": the command line turns them into one
line on stderr and exit code 2."""

from __future__ import annotations


class InputError(Exception):
    """Bad input: names the file (or command-line option), the field and what is wrong."""

    def __init__(self, source: str, field: str | None, message: str):
        self.source = str(source)
        self.field = field
        self.message = " ".join(str(message).split())
        super().__init__(str(self))

    def __reduce__(self):
        # Crosses process boundaries (worker pools) with its three parts intact.
        return (InputError, (self.source, self.field, self.message))

    def __str__(self) -> str:
        where = f"{self.source}: {self.field}" if self.field else self.source
        return f"{where}: {self.message}"


def describe(exc: BaseException) -> str:
    """An exception in one line: its type, and its message when it has one."""
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__
