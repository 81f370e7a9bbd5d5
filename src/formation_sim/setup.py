"""Packaging for formation_sim: a pip-installable and ament_python package."""

from setuptools import find_namespace_packages, setup

package_name = 'formation_sim'

setup(
    name=package_name,
    version='0.1.0',
    description='Scenarios, exact world, engine, simulator node and recorder for formation control',
    license='Apache-2.0',
    python_requires='>=3.11',
    # Namespace search: a subpackage is shipped whether or not it has an __init__.py.
    packages=find_namespace_packages(include=[package_name, f'{package_name}.*'], exclude=['*.__pycache__']),
    package_data={package_name: ['model/scenarios/*.yaml']},
    # What ament expects of an ament_python package: the index marker and package.xml in share/.
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{package_name}']),
        (f'share/{package_name}', ['package.xml']),
    ],
    # formation_agent, formation_msgs_py and the ROS packages come from the workspace
    # (package.xml), not from PyPI.
    install_requires=['setuptools', 'numpy', 'scipy', 'PyYAML', 'matplotlib', 'mcap', 'rosbags'],
    # `colcon test` runs pytest (setup.cfg points it at this package's tests in the repository).
    extras_require={'test': ['pytest']},
    zip_safe=False,
    entry_points={
        'console_scripts': [
            'formation = formation_sim.cli:main',
            'formation_sim = formation_sim.runtime.nodes.sim_node:entry_point',
            'formation_recorder = formation_sim.runtime.nodes.recorder:entry_point',
            'formation_robot = formation_sim.runtime.nodes.robot_node:entry_point',
            'formation_coordinator = formation_sim.runtime.nodes.coordinator:entry_point',
        ]
    },
)
