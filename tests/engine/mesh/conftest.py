"""Tests of ``ctui.engine.mesh``; shared fixtures are in ../conftest.py and helpers in tests/support.py."""
