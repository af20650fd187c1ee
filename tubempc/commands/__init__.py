"""Subcommands of the ``tubempc`` CLI, one module each; heavy libraries are imported inside the commands."""
