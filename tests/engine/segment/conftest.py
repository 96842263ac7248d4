"""Tests of ``ctui.engine.segment``; shared fixtures are in ../conftest.py and helpers in tests/support.py."""
