"""The ``rimcl`` command line: thin click wrappers around the library."""
