"""The unit tier imports no rclpy (``tests/unit/test_test_layout.py`` reads the sources).

What reading cannot see, an import inside a function of a product module, fails here at run
time: during each unit test ``import rclpy`` raises ``ImportError`` when this process has not
imported rclpy yet (``make test`` runs the node tests in the same worker processes, which
import it: there the check cannot tell, and a run of ``tests/unit`` alone does)."""
import sys

import pytest


@pytest.fixture(autouse=True)
def _no_rclpy(monkeypatch):
    if 'rclpy' not in sys.modules:
        monkeypatch.setitem(sys.modules, 'rclpy', None)
    yield
