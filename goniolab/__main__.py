"""``python -m goniolab``: the same command line as the ``goniolab`` script."""

from goniolab.cli import console

console()
