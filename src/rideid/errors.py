"""Exception hierarchy.

Every error a user can cause by what they give rideid (files, keys, columns,
arguments) is a :class:`RideidError`; the command line turns it into one line
on stderr and exit code 2. Anything else is a bug (exit code 1).
"""

from __future__ import annotations


class RideidError(Exception):
    """Base class of the errors rideid raises for bad input."""


class DataError(RideidError, ValueError):
    """A file, key, column or value is missing, malformed or out of range."""


class ScaleError(DataError):
    """No absolute scale anchor is known (see SPEC §1 "Identifiability")."""


class ArgumentError(RideidError, ValueError):
    """A function or command-line argument is invalid."""


class ModelValidityWarning(UserWarning):
    """The linear model's assumptions (e.g. tires on the road) are violated."""


class DataWarning(UserWarning):
    """Something in the data looks suspicious but is usable."""
