"""Packaging for formation_msgs_py: a pip-installable and ament_python package."""

from setuptools import find_namespace_packages, setup

package_name = 'formation_msgs_py'

setup(
    name=package_name,
    version='0.1.0',
    description='ROS-free formation message dataclasses and their encoding over standard Jazzy types',
    license='Apache-2.0',
    python_requires='>=3.11',
    # Namespace search: a subpackage is shipped whether or not it has an __init__.py.
    packages=find_namespace_packages(include=[package_name, f'{package_name}.*'], exclude=['*.__pycache__']),
    # Fast DDS's settings for every node process (middleware.FASTDDS_PROFILE), robots' agents too.
    package_data={package_name: ['fastdds_profile.xml']},
    # What ament expects of an ament_python package: the index marker and package.xml in share/.
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{package_name}']),
        (f'share/{package_name}', ['package.xml']),
    ],
    # ROS message packages come from ROS (package.xml), not from this list.
    install_requires=['setuptools'],
    # `colcon test` runs pytest (setup.cfg points it at this package's tests in the repository).
    extras_require={'test': ['pytest']},
    zip_safe=True,
)
