"""``python -m pwsdyn.cli``: the ``pwsdyn`` command."""

from . import main

main()
