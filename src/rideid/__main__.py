"""``python -m rideid``: the command line."""

import sys

from .cli import console

console(sys.argv[1:])
