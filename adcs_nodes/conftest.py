"""``colcon test`` runs pytest in this directory (setup.cfg: ``testpaths = ../tests``): the
project's tests are the repository's ``tests/`` and read the whole repository (scenarios, the
Makefile, docs), so they run from the repository's ``ros2_ws`` only. Elsewhere (a workspace of
your own) this stops with that reason, rather than passing with 0 tests."""
import os

import pytest

TESTS = os.path.join(os.path.dirname(os.path.realpath(__file__)), os.pardir, 'tests')


def pytest_configure(config):
    if not os.path.isdir(TESTS):
        raise pytest.UsageError(
            "adcs_nodes: the project's tests are the repository's tests/ and need the whole "
            f'repository ({os.path.normpath(TESTS)} does not exist): run `colcon test` in its '
            'ros2_ws, or `make test`')
