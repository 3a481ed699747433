"""ament_python package of the flight software and tools (``ros2 run adcs_nodes <node>``)."""
from setuptools import find_packages, setup

PACKAGE = 'adcs_nodes'

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml']),
    ],
    install_requires=['setuptools'],
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
            'compose = adcs_nodes.tools.compose:main',
        ],
    },
)
