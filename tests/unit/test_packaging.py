"""What a plain (not ``--symlink-install``) colcon build installs: every source directory of the
two Python packages is a package ``find_packages`` finds (a directory without ``__init__.py``
works from the source tree but is left out of an installed workspace)."""
import os

from setuptools import find_packages

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_every_module_directory_is_an_installed_package():
    for pkg in ('adcs_nodes', 'sim_node'):
        base = os.path.join(ROOT, pkg)
        found = set(find_packages(base, exclude=['test']))
        dirs = {os.path.relpath(d, base).replace(os.sep, '.')
                for d, _, files in os.walk(os.path.join(base, pkg))
                if '__pycache__' not in d and any(f.endswith('.py') for f in files)}
        assert dirs <= found, f'{pkg}: not installed by setup.py: {sorted(dirs - found)}'
