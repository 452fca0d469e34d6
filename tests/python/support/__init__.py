"""Helpers shared by test files in different folders (problem texts, band problems); tests
import them as ``support.NAME`` (tests/python is on sys.path through conftest.py)."""
