"""The built-in problem files, installed as the package data ``wingopt._problems`` (see setup.py)."""
