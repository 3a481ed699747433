"""ament_python package of the simulated world (``ros2 run sim_node <node>``)."""
from setuptools import find_packages, setup

PACKAGE = 'sim_node'

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
    description='Simulated world of the satellite ADCS: orbit, field, dynamics, sensors.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'dynamics = sim_node.nodes.dynamics:main',
            'environment = sim_node.nodes.environment:main',
            'sensor_node = sim_node.nodes.sensor_node:main',
            'magnetometer = sim_node.nodes.sensor_node:main_magnetometer',
            'horizon_sensor = sim_node.nodes.sensor_node:main_horizon_sensor',
            'star_tracker = sim_node.nodes.sensor_node:main_star_tracker',
            'gyro = sim_node.nodes.sensor_node:main_gyro',
            'wheel_tachometer = sim_node.nodes.sensor_node:main_wheel_tachometer',
        ],
    },
)
