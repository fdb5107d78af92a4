"""Registers the shared fixtures of tests/fixtures/ once, for every test."""

import pytest

# the helpers test modules import from tests.fixtures: rewrite their asserts too
pytest.register_assert_rewrite("tests.fixtures")

pytest_plugins = [
    "tests.fixtures.recordings",
    "tests.fixtures.datasets",
    "tests.fixtures.serve",
    "tests.fixtures.recipes",
    "tests.fixtures.views",
]
