"""For ROS Python tooling that still looks for a setup.py: everything is in pyproject.toml."""

from setuptools import setup

setup()
