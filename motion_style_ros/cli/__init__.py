"""The ``motion-style`` command line: one module per subcommand (see ``main.py``)."""
