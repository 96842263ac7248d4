"""Tests of ``ctui.engine.measure``; shared fixtures are in ../conftest.py and helpers in tests/support.py."""
