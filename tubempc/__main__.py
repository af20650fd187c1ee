"""``python -m tubempc``: same as the ``tubempc`` command."""

from tubempc.cli import main

main()
