"""ament_python package of the flight software and tools (``ros2 run adcs_nodes <node>``).

Installs, besides the Python package: the launch file (``share/adcs_nodes/launch``) and the
scenarios (``share/adcs_nodes/scenarios``, from the repository's ``scenarios/``). ``colcon test``
runs the project's tests (``../tests``, config in setup.cfg; ``conftest.py`` says where they are
when they are not there).
"""
import glob
import os

from setuptools import find_packages, setup

PACKAGE = 'adcs_nodes'
# adcs_nodes/scenarios is a symlink to the repository's scenarios/ (colcon wants data_files
# inside the package directory)
HERE = os.path.dirname(os.path.realpath(__file__))


def files(pattern):
    """Paths matching ``pattern``, relative to this package's real directory (colcon wants
    relative data_files)."""
    return sorted(os.path.relpath(p, HERE) for p in glob.glob(os.path.join(HERE, pattern)))


SCENARIOS = files('scenarios/*.yaml')
if not SCENARIOS:
    raise FileNotFoundError(     # not SystemExit: colcon's run_setup would swallow the text
        f'adcs_nodes: no scenarios in {os.path.join(HERE, "scenarios")}: in the repository it is '
        'a link to ../scenarios, which a plain copy breaks. Copy the package with its links '
        'followed (cp -rL), or copy the repository\'s scenarios/*.yaml there.')

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    # the Fast DDS profile (tools/run/launcher), a stored measurement (tools/analyse)
    package_data={PACKAGE: ['config/*.xml', 'tools/analyse/*.json']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml']),
        ('share/' + PACKAGE + '/launch', files('launch/*.launch.py')),
        ('share/' + PACKAGE + '/scenarios', SCENARIOS),
    ],
    install_requires=['setuptools'],
    tests_require=['pytest'],
    zip_safe=True,
    maintainer='ADCS maintainers',
    maintainer_email='adcs@example.org',
    description='Flight software of the satellite ADCS and the adcs launcher CLI.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'adcs = adcs_nodes.tools.cli:main',
            'recorder = adcs_nodes.nodes.recorder:main',
            'estimator = adcs_nodes.nodes.estimator:main',
            'magnetic_controller = adcs_nodes.nodes.controller:main_magnetic',
            'bdot_controller = adcs_nodes.nodes.controller:main_bdot',
            'controller = adcs_nodes.nodes.controller:main',
            'guidance = adcs_nodes.nodes.guidance:main',
            'controller_manager = adcs_nodes.nodes.controller_manager:main',
            'static_mount = adcs_nodes.nodes.tf:main',
            'slew_action = adcs_nodes.nodes.slew_action:main',
            'compose = adcs_nodes.tools.run.compose:main',
        ],
    },
)
