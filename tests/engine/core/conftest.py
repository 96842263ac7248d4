"""Tests of ``ctui.engine.core``; shared fixtures are in ../conftest.py and helpers in tests/support.py."""
