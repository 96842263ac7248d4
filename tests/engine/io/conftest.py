"""Tests of ``ctui.engine.io``; shared fixtures are in ../conftest.py and helpers in tests/support.py."""
