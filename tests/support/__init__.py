"""Helpers that several test modules share (fixtures live in the ``conftest.py`` files)."""
from pathlib import Path

#: The repository's root folder.
ROOT = Path(__file__).resolve().parents[2]
