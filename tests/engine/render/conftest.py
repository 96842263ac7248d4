"""Tests of ``ctui.engine.render``; shared fixtures are in ../conftest.py and helpers in tests/support.py."""
