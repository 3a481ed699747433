"""The suite is collected without package ``__init__`` files (pytest's rootdir imports), so two
test files with the same basename in different folders break collection of the whole run
("import file mismatch"); this catches it by name, before a clean clone does."""
import collections
import os

TESTS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_test_file_basenames_are_unique():
    where = collections.defaultdict(list)
    for folder, _, files in os.walk(TESTS):
        for name in files:
            if name.startswith('test_') and name.endswith('.py'):
                where[name].append(os.path.relpath(os.path.join(folder, name), TESTS))
    dups = {name: paths for name, paths in where.items() if len(paths) > 1}
    assert not dups, f'test files with the same basename: {dups}'
