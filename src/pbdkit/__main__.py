"""``python -m pbdkit``: the ``pbdkit`` command."""

from pbdkit.apps import main

main()
