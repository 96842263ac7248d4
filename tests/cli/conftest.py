"""Command-line tests: `ctui CMD` end to end, in this process (``support.cli_streams``) where the
process itself is not what is tested, else in a subprocess or a pseudo-terminal."""
