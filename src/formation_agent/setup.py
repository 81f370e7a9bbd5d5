"""Packaging for formation_agent: a pip-installable and ament_python package."""

from glob import glob

from setuptools import Extension, find_namespace_packages, setup

package_name = 'formation_agent'

# The compiled core (docs/COMPILED_CORE.md): plain C through the CPython API, so that building it
# needs only the C compiler and the Python headers that colcon and pip already use. The flags keep
# IEEE semantics (no contraction into FMA, no fast-math) so that it gives the pure-Python path's
# floats; `optional`: where it cannot be built the install goes on and the pure-Python path runs.
compiled_core = Extension(
    f'{package_name}.core._fastcore',
    sources=[f'{package_name}/core/_fastcore.c'],
    extra_compile_args=['-O2', '-ffp-contract=off', '-fno-fast-math', '-std=c11'],
    optional=True,
)

setup(
    name=package_name,
    version='0.1.0',
    description='Event-triggered formation agent (Yi et al. 2017): ROS-free ETA core and its node',
    license='Apache-2.0',
    python_requires='>=3.11',
    # Namespace search: a subpackage is shipped whether or not it has an __init__.py.
    packages=find_namespace_packages(include=[package_name, f'{package_name}.*'], exclude=['*.__pycache__']),
    # What ament expects of an ament_python package: the index marker and package.xml in share/.
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{package_name}']),
        (f'share/{package_name}', ['package.xml']),
        # Example parameter files for robots (README, "Running on robots"), also in share/ where ROS
        # packages keep them (regular and colcon installs; an editable install gets no data_files).
        (f'share/{package_name}/config', sorted(glob(f'{package_name}/config/*.params.yaml'))),
    ],
    # ... and inside the package, so that every install has them (`python3 -m formation_agent.config`).
    package_data={f'{package_name}.config': ['*.params.yaml']},
    # formation_msgs_py and the ROS packages come from the workspace (package.xml), not from PyPI.
    install_requires=['setuptools', 'numpy', 'scipy'],
    # `colcon test` runs pytest (setup.cfg points it at this package's tests in the repository).
    extras_require={'test': ['pytest']},
    ext_modules=[compiled_core],
    zip_safe=False,
    entry_points={'console_scripts': ['formation_agent = formation_agent.ros.main:entry_point']},
)
