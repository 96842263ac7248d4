"""Fuzz and regression-corpus tests. The engine is ``test_fuzz_harness.py`` (reader campaigns in a
worker subprocess) and ``fuzz_cli.py`` (the commands end to end); ``regression_corpus/`` holds every
file that once broke a reader, run by test_fuzz_corpus.py."""
