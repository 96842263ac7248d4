"""Tests of ``ctui.engine.actions``; shared fixtures are in ../conftest.py and helpers in tests/support.py."""
