"""Package layout that pyproject.toml cannot express: the built-in problem files.

They live in the repository's top-level ``problems/`` (where users and docs look for them) and
are shipped inside the package as ``wingopt._problems`` (read with ``importlib.resources``).
Everything else is in pyproject.toml.
"""

from setuptools import find_packages, setup

setup(
    packages=[*find_packages(include=["wingopt", "wingopt.*"]), "wingopt._problems"],
    package_dir={"wingopt._problems": "problems"},
    package_data={"wingopt": ["py.typed"], "wingopt._problems": ["*.toml"]},
)
