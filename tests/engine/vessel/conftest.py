"""Tests of ``ctui.engine.vessel``; shared fixtures are in ../conftest.py and helpers in tests/support.py."""
